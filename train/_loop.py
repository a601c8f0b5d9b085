"""The training loop: the paper's recipe on random tile-aligned crops, resumable and seeded.

L1 between the transformed target and the network output (Section 3.3), the clamped transform with
``mu_Y`` measured on the training targets (or the logistic one), RMSprop with learning rate 1e-4 and
an exponential decay of ``1 - 1e-4`` per step (appendix), validation on whole frames of held-out
scenes, and a safety margin calibrated on that validation data.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import logging
import math
import os
import platform
import shlex
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from rtp import sdk
from rtp.capture import DatasetError, DatasetReader, TargetError, TargetStore, check_memory
from rtp.evaluate import scores
from rtp.metrics import MetricParameterError, device_name, known_metrics, metric_info, metric_plugins, resolve_device
from rtp.sdk.files import LOCK_NAME, check_output, writer_lock

from . import checkpoint as ckpt
from . import transforms as tt
from ._augment import SYMMETRIES, augment_batch, move_tiles, packed_cell
from ._frames import Frame, crop_batch
from ._recipe import RecipeError, check_fields, load_recipe, normal_fields
from ._safety import calibrate_safety
from .model import ARCHS, HEADS, Network, build_network, keep_outputs

__all__ = ["TrainConfig", "TrainResult", "step_bytes", "train"]

log = logging.getLogger("rtp.train")



class TrainingDivergedError(sdk.RtpError):
    """The loss or the weights became NaN or infinite: the training diverged (too high a learning rate for
    the data, or non-finite input planes). It stops at once, before the diverged weights replace the last
    checkpoint on disk, which stays as it was. Exit code 1 (the job ran and failed)."""

    exit_code = sdk.EXIT_FAILED


@dataclass
class TrainConfig:
    """Everything :func:`train` needs: the data, the metric and the checkpoint path, then the recipe (a shipped
    one by :meth:`from_recipe`, ``rtp train --config``; docs/training.md lists the fields). Each field's comment
    says what it sets; :func:`check_config` refuses a configuration before any work."""

    #: A dataset folder with targets (``rtp targets``), or several, comma-separated, whose samples train and
    #: validate together (each with the metric's targets computed with the same parameters; no sample id twice).
    data: str
    metric: str
    out: str
    tile: int = sdk.DEFAULT_TILE_SIZE
    outputs: tuple[str, ...] = sdk.DEFAULT_OUTPUTS
    inputs: tuple[str, ...] = sdk.DEFAULT_INPUTS
    transform: str = "clamped"
    logistic_k: float = 10.0
    #: The network: ``paper`` (the paper's, the reference) or ``fast`` (rtp's, train/model.py).
    arch: str = "paper"
    width: int = 16
    head: str = "paper"
    #: 3x3 blocks of the fast network.
    depth: int = 3
    #: Stride (and kernel) of the fast network's first convolution: 1, 2, 4 or 8.
    stem: int = 4
    #: 2: each block of the fast network after a pool doubles its channels (1: ``width`` throughout).
    grow: int = 1
    #: With grow 2: the most channels a block doubles to (0: no cap).
    max_width: int = 0
    #: The fast network's 3x3 blocks depthwise-separable (a 3x3 per channel, then a 1x1 across them).
    separable: bool = False
    #: Only the fast network's blocks at tile resolution (after its last pool) depthwise-separable: with
    #: grow 2, a 64-channel end at about a seventh of its cost.
    separable_tail: bool = False
    #: Channels of the fast network's blocks at tile resolution (after its last pool), whatever ``grow``
    #: gives them; 0: as ``width`` and ``grow`` say.
    tail_width: int = 0
    #: Hidden channels of the fast network's head: 0, a linear 1x1; N, a 1x1 to N, BatchNorm, ReLU, then
    #: the 1x1 to the outputs (a per-tile MLP, almost free at tile resolution).
    head_width: int = 0
    #: An odd window K (in tiles): the fast network appends the mean of its last features over K x K
    #: tiles before the head (train/model.py ``ContextPool``); 0: none.
    context_pool: int = 0
    #: Blocks of the fast network at twice the tile's scale, whose features join after its first block at
    #: tile resolution (train/model.py ``CoarseContext``: a wider, learned view of the neighbourhood); 0: none.
    coarse: int = 0
    #: Channels of those blocks.
    coarse_width: int = 64
    #: Input channels (names among ``inputs``) whose variance inside each reduced rate's blocks the
    #: fast network reads beside its stem (train/model.py ``BlockContrast``); empty: none.
    block_contrast: tuple[str, ...] = ()
    #: The cell (pixels) the block contrast is measured over and joins the network at: 0, the stem's
    #: (after the stem); twice it, after the first pool (a quarter of the positions: cheaper).
    contrast_cell: int = 0
    #: With a contrast cell over 4 pixels: also the worst 4x4 cell's contrast in each cell, beside the
    #: mean (``BlockContrast(tile_max=True)``).
    contrast_max: bool = False
    #: 2: the fast network's stem as two convolutions (for stem 4: two 2x2 stride-2 reads with a ReLU
    #: between, at half resolution); 1: one ``stem x stem`` read.
    stem_layers: int = 1
    #: The fast network's features after its first block and pool divided by their energy per
    #: position, its log appended (train/model.py ``EnergyNorm``: LPIPS's normalisation).
    energy_norm: bool = False
    #: Random flips and transposes of each crop (the 8 symmetries of the square), with the targets and
    #: the direction-dependent channels changed to match (train/_augment.py).
    augment: bool = False
    #: Random left-right mirrors of each crop only (the one symmetry a level keeps: up stays up), the
    #: targets and normal x / motion x mirrored with it, ``.blocks`` and ``.tiles`` planes by whole cells
    #: (train/_augment.py); with ``context`` too.
    mirror: bool = False
    #: Training loss in transformed space: ``l1`` (the paper's), ``mse`` (what R² scores) or
    #: ``huber`` (quadratic below 0.1, linear above) or ``bce`` (cross-entropy, soft targets) or
    #: ``quantile`` (the pinball loss of ``quantile``: the network predicts that quantile of a tile's
    #: target given its inputs, a safety margin of its own per tile).
    loss: str = "l1"
    #: With ``loss: quantile``: the quantile predicted, in (0, 1) (0.5: the median, as ``l1``).
    quantile: float = 0.75
    #: Extra weight of the tiles whose target lies near the default threshold (in transformed space, a
    #: Gaussian band of half-width ``FOCUS_WIDTH`` around it): each tile's loss is weighted
    #: ``1 + focus * exp(-d^2 / 2 FOCUS_WIDTH^2)``, ``d`` its target's distance from the threshold, so the
    #: network spends its accuracy where the SDK's rate decisions are made. 0: off (every tile alike).
    focus: float = 0.0
    #: Decay of an exponential moving average of the weights (and BatchNorm statistics), updated
    #: every step; the average is what is validated, calibrated and saved. 0: off (the raw weights).
    ema: float = 0.0
    #: Teachers: exported models (.onnx) of the same metric, tile size and target transform, whose
    #: mean prediction on each whole training frame is mixed into the targets with weight
    #: ``distill`` (knowledge distillation: an ensemble's smoother function taught to one network).
    teachers: tuple[str, ...] = ()
    distill: float = 0.5
    #: Auxiliary metrics (multi-task training): the network also learns to predict these metrics'
    #: targets on the same tiles (extra outputs of the head, each metric in its own transform), so its
    #: features are taught by their supervision too; the saved network keeps only ``metric``'s outputs
    #: (train/model.py ``keep_outputs``), so the extra outputs cost nothing at run time. Fast network only.
    aux_metrics: tuple[str, ...] = ()
    #: Weight of the auxiliary metrics' mean loss beside the metric's own.
    aux_weight: float = 0.5
    steps: int = 3000
    batch: int = 8
    crop: int = 128
    #: Pixels of input read around each crop (a multiple of the tile) whose tiles are not scored, unless
    #: they lie on the frame's border: the scored tiles then see what they see in a whole frame, not
    #: the zero padding at the crop's edge (with 128-pixel crops and no context, 48 of a crop's 64
    #: tiles are within reach of its edge for rtp's fast network, 28 pixels past a tile, against 13% of a
    #: 1280x720 frame's tiles; 28 of 64 for the paper's, 16 pixels past a tile, against 7%). 0: off.
    context: int = 0
    lr: float = 1e-4
    lr_decay: float = 1e-4
    #: ``rmsprop`` (the paper's) or ``adamw`` (Adam with decoupled ``weight_decay``).
    optimizer: str = "rmsprop"
    #: ``exponential`` (the paper's: the learning rate times ``1 - lr_decay`` each step) or ``cosine``
    #: (a linear warm-up over the first 2% of ``steps``, then half a cosine down to zero at ``steps``).
    schedule: str = "exponential"
    weight_decay: float = 0.0
    val_scenes: tuple[str, ...] = ()
    #: Hold out the maps of this split of ``splits`` that the data holds (``val_scenes`` wins; if the
    #: data holds none of the split's maps, the last scene, with a warning).
    val_split: str | None = None
    splits: str | None = None
    val_every: int = 250
    save_every: int = 250
    seed: int = 0
    safety_quantile: float | None = None
    default_threshold: float | None = None
    max_samples: int | None = None
    #: At most this many training samples of each map and motion profile (the first by sample id); the
    #: validation maps' samples are all kept. With a second dataset in ``data`` (another motion profile),
    #: it keeps the loader's memory where one dataset's is.
    per_scene: int | None = None
    #: Where the network trains: ``"cpu"``, ``"cuda"`` (or ``"cuda:N"``), ``"mps"``, or ``"auto"`` (the
    #: first GPU torch sees, else the CPU). The machine's, not the recipe's: a recipe cannot set it, a
    #: checkpoint does not compare it (a training resumes on another device) and the model's provenance
    #: records the device it ended on. The samples stay in host memory; each batch is copied over.
    device: str = "auto"
    #: Where the hyper-parameters came from (``Recipe.provenance()``), recorded in the model's provenance.
    recipe: dict[str, Any] | None = None

    @classmethod
    def from_recipe(
        cls,
        recipe: str | os.PathLike[str],
        *,
        data: str,
        metric: str,
        out: str,
        scenes: str | Path | None = None,
        **overrides: Any,
    ) -> TrainConfig:
        """A configuration from a recipe (a YAML path, or ``"shipped"``: the shipped models' recipe),
        resolved for ``metric``; keyword ``overrides`` (TrainConfig fields) win over the recipe.
        The recipe's ``val_split`` holds out that split's maps of ``scenes`` (default: the recipe's ``splits``,
        else the split list shipped with rtp) unless ``val_scenes`` is overridden; a ``val_split`` or ``splits``
        override wins over the recipe's as any other does. ``splits`` (or ``scenes``) with no ``val_split`` to read
        it and no ``val_scenes`` is refused (:class:`RecipeError` where the recipe set it)."""
        import dataclasses

        from rtp.capture.scenes import map_names

        if scenes is not None and not isinstance(scenes, (str, os.PathLike)):
            raise sdk.ParameterError(f"scenes: expected None or the path of a scenes.yaml, got {type(scenes).__name__}",
                                     "scenes")
        unknown = sorted(set(overrides) - {f.name for f in dataclasses.fields(cls)})
        if unknown:  # (a TypeError from the constructor's keywords)
            raise sdk.ParameterError(f"unknown TrainConfig field(s) {', '.join(unknown)}", unknown[0])
        overrides = normal_fields(overrides)  # (numpy's numbers as Python's, in the provenance too)
        r = load_recipe(recipe, metric)
        values = {**r.values, **overrides}
        # The caller's val_split and splits (or scenes) win over the recipe's, as every override does (the
        # recipe's val_split replaced the caller's, and scenes=None the splits the caller or the recipe gave:
        # another split's maps were held out than the provenance recorded)
        val_split = overrides["val_split"] if "val_split" in overrides else r.val_split
        splits = scenes if scenes is not None else values.get("splits")
        if "val_scenes" not in overrides and val_split is not None:
            try:
                map_names(val_split, splits)  # an unknown split is refused now, not after loading the data
            except sdk.ParameterError as err:
                if err.name != "split":  # (the splits file's own problem, named as it is)
                    raise
                if "val_split" in overrides or r.val_split is None:
                    raise sdk.ParameterError(f"val_split: {err}", "val_split") from None
                raise RecipeError(f"recipe {r.name} sets val_split: {val_split}, which does not fit: {err}",
                                  "val_split") from None
            values.update(val_split=val_split, splits=None if splits is None else str(splits))
        elif "val_scenes" not in overrides and splits is not None:
            # (splits is read only to hold out val_split's maps: without one it was recorded in the checkpoint and
            # ignored, and the last scene held out, not a split of it)
            why = (f"read only with val_split (the split of it whose maps are held out), and neither recipe {r.name} "
                   f"nor the training sets one: the last scene would be held out and {splits} ignored")
            if scenes is not None or "splits" in overrides:
                raise sdk.ParameterError(f"splits: {why}; give val_split (or val_scenes) with it, or leave it out",
                                         "splits")
            raise RecipeError(f"recipe {r.name} sets splits: {splits}, {why}; add val_split to the recipe (val_split: "
                              f"validation), or remove splits", "splits")
        prov = r.provenance()
        # (the device is the machine's, not a hyper-parameter: the provenance names it apart)
        recipe_values = {**r.values, "val_split": r.val_split}
        changed = {k: v for k, v in overrides.items()
                   if k != "device" and (k not in recipe_values or recipe_values[k] != v)}
        if changed:  # what the command line changed: a model says how it was really trained
            prov["overrides"] = {k: list(v) if isinstance(v, tuple) else v for k, v in changed.items()}
        cfg = cls(data=data, metric=metric, out=out, recipe=prov, **values)
        try:
            cfg = check_config(cfg)  # a recipe's ranges and combinations too, when it is read (train() checks again)
        except sdk.ParameterError as err:
            key = err.name
            if key is None or key not in r.values or key in overrides:
                raise
            # (a conflict with a value the caller did not give: "--head-width: the fast network's option" for
            # --arch paper, where the recipe had set head_width)
            raise type(err)(f"recipe {r.name} sets {key}: {_shown(r.values[key])}, which does not fit: {err}; override "
                            f"it or train with another recipe", key) from None
        _check_used(cfg, values, r.name, overrides)
        return cfg


#: Fields read only in some configurations (field, whether ``cfg`` reads it, what it is read with): set by a
#: recipe or the caller where it is not read, it trained nothing while the provenance recorded it.
_READ_ONLY_WITH: tuple[tuple[str, Callable[[TrainConfig], bool], str], ...] = (
    ("quantile", lambda c: c.loss == "quantile", "loss quantile"),
    ("logistic_k", lambda c: c.transform == "logistic", "transform logistic"),
    ("distill", lambda c: bool(c.teachers), "teachers"),
    ("aux_weight", lambda c: bool(c.aux_metrics), "aux_metrics"),
    ("coarse_width", lambda c: c.coarse > 0, "coarse"),
    ("lr_decay", lambda c: c.schedule == "exponential", "schedule exponential"),
)


def _check_used(cfg: TrainConfig, given: Mapping[str, Any], recipe: str, overrides: Mapping[str, Any]) -> None:
    """Refuse a field ``given`` (by the recipe ``recipe`` or the caller's ``overrides``) that ``cfg`` never reads."""
    for key, read, needs in _READ_ONLY_WITH:
        if key in given and not read(cfg):
            if key in overrides:
                raise sdk.ParameterError(f"{key}: read only with {needs}, got {key} {_shown(given[key])} without it "
                                         f"(it would be recorded and ignored)", key)
            raise sdk.ParameterError(f"recipe {recipe} sets {key}: {_shown(given[key])}, read only with {needs}, which "
                                     f"it does not train with (it would be recorded and ignored): remove it from the "
                                     f"recipe or train with {needs}", key)


def _shown(value: Any) -> str:
    return ",".join(value) if isinstance(value, (tuple, list)) else str(value)


@dataclass
class TrainResult:
    checkpoint: Path
    steps: int
    val: dict[str, Any] = field(default_factory=dict)
    safety: float = 0.0
    under_share: float = 0.0
    dead_outputs: list[str] = field(default_factory=list)  # outputs that predict a constant (see DEAD_OUTPUT_STD)


_RESUME_KEYS = ("data", "metric", "tile", "outputs", "inputs", "transform", "logistic_k", "width", "batch", "crop",
                "lr", "lr_decay", "weight_decay", "val_scenes", "seed", "max_samples")


def data_folders(data: str | os.PathLike[str]) -> list[str]:
    """The dataset folders of ``TrainConfig.data`` (one, or several comma-separated), each named once; a folder
    whose name holds a comma is taken whole."""
    if os.path.isdir(str(data)):
        return [str(data)]
    folders = [f.strip() for f in str(data).split(",")]
    if not all(folders) or len(set(folders)) != len(folders):
        raise sdk.ParameterError(f"data: expected a dataset folder or several, comma-separated, each once, got {str(data)!r}",
                                 "data")
    return folders


def _same_folders(a: object, b: object) -> bool:
    """Whether two ``data`` values name the same folders: spelled alike but for separators and dots
    (``data/train/`` and ``data/train``), or each pair the same folder on disk (``data/train`` and its absolute
    path, or a link to it: a resume from a script that spells it absolute was refused as another configuration);
    the samples' own check still holds a resume to the same ids."""
    if not isinstance(a, str) or not isinstance(b, str):
        return False
    try:
        was, now = data_folders(a), data_folders(b)
    except sdk.ParameterError:
        return False
    return len(was) == len(now) and all(os.path.normpath(x) == os.path.normpath(y) or _same_dir(x, y)
                                        for x, y in zip(was, now))


def _same_dir(a: str, b: str) -> bool:
    """Whether ``a`` and ``b`` are one existing folder."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


class _Sources:
    """The samples and targets of one or more dataset folders as one dataset: what :func:`train` reads
    through ``DatasetReader`` and ``TargetStore``. The folders must not share a sample id, and each must
    hold the targets :func:`train` needs, computed with the same parameters (a JNYang of another Weber
    ``l`` is another metric)."""

    def __init__(self, data: str, metric: str, aux_metrics: Sequence[str] = ()) -> None:
        self.folders = data_folders(data)
        self.readers = [DatasetReader(f) for f in self.folders]
        self.stores = [TargetStore(f) for f in self.folders]
        metrics = [metric, *aux_metrics]
        for f, store in zip(self.folders, self.stores):
            for want, what in (([metric], ""), (list(aux_metrics), " (aux_metrics)")):
                absent = [m for m in want if m not in store.metrics]
                if absent:
                    raise TargetError(f"{f} has no {', '.join(absent)} targets{what}; run `rtp targets "
                                      f"{shlex.quote(str(f))} --metrics {','.join(absent)}`")
        for m in metrics:
            params = {f: s.metrics[m] for f, s in zip(self.folders, self.stores)}
            if len({json.dumps(v, sort_keys=True) for v in params.values()}) > 1:
                raise TargetError(f"the {m} targets of the datasets were computed with different parameters: "
                                  + "; ".join(f"{f}: {v}" for f, v in params.items()))
        self.where: dict[str, int] = {}
        for k, reader in enumerate(self.readers):
            for s in reader:
                if s.id in self.where:
                    raise DatasetError(f"sample {s.id} is in both {self.folders[self.where[s.id]]} and "
                                       f"{self.folders[k]}; training reads each sample once")
                self.where[s.id] = k
        #: the targets' parameters per metric (the same in every folder)
        self.metrics: dict[str, Any] = dict(self.stores[0].metrics)

    def __iter__(self) -> Any:
        for reader in self.readers:
            yield from reader

    def __getitem__(self, sample_id: str) -> Any:
        return self.readers[self.where[sample_id]][sample_id]

    def load(self, sample_id: str, metric: str, tile: int) -> np.ndarray:
        return self.stores[self.where[sample_id]].load(sample_id, metric, tile)


class _Split:
    """Inputs (float16, ``.blocks`` planes packed, to fit many frames in memory) and targets of one side of the split."""

    def __init__(self, reader: _Sources, store: _Sources, ids: Sequence[str], cfg: TrainConfig,
                 read: Callable[[], None] = lambda: None) -> None:
        rows = [sdk.PREDICTED_RATES.index(r) for r in cfg.outputs]
        self.ids = list(ids)
        self.x: list[Frame] = []
        self.y: list[np.ndarray] = []
        #: per sample, each auxiliary metric's targets (TrainConfig.aux_metrics), in that order
        self.aux: list[list[np.ndarray]] = []
        for i in self.ids:  # ``read()`` after each sample
            self.x.append(Frame(reader[i].inputs(cfg.inputs), cfg.inputs))
            self.y.append(store.load(i, cfg.metric, cfg.tile)[rows])
            self.aux.append([store.load(i, m, cfg.tile)[rows] for m in cfg.aux_metrics])
            read()


#: Training losses, in transformed space (TrainConfig.loss).
_LOSSES: dict[str, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]] = {
    "l1": F.l1_loss,
    "mse": F.mse_loss,
    "huber": lambda p, t: F.huber_loss(p, t, delta=0.1),
    # cross-entropy with the target as a soft label: its gradient at the logit is p - t, which does not
    # vanish where the sigmoid saturates (targets at the transform's clamp, 1.0)
    "bce": lambda p, t: F.binary_cross_entropy(p.clamp(1e-6, 1.0 - 1e-6), t.clamp(0.0, 1.0)),
}
#: TrainConfig.loss's names (``quantile`` takes TrainConfig.quantile, so it is built in :func:`_loss`).
LOSSES = (*_LOSSES, "quantile")


def _pinball(q: float) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """The pinball loss of quantile ``q`` per element: minimised by that quantile of the target."""
    return lambda p, t: torch.maximum(q * (t - p), (q - 1.0) * (t - p))


def _mean_pinball(q: float) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """The pinball loss of quantile ``q``, averaged (TrainConfig.loss ``quantile``)."""
    element = _pinball(q)
    return lambda p, t: element(p, t).mean()


#: The same losses per element, for a weighted mean (TrainConfig.focus).
_ELEMENT_LOSSES: dict[str, Callable[[torch.Tensor, torch.Tensor], torch.Tensor]] = {
    "l1": lambda p, t: (p - t).abs(),
    "mse": lambda p, t: (p - t) ** 2,
    "huber": lambda p, t: F.huber_loss(p, t, delta=0.1, reduction="none"),
    "bce": lambda p, t: F.binary_cross_entropy(p.clamp(1e-6, 1.0 - 1e-6), t.clamp(0.0, 1.0), reduction="none"),
}
#: Half-width (one standard deviation, transformed space) of TrainConfig.focus's band around the threshold.
FOCUS_WIDTH = 0.15


def _focused(loss: str, focus: float, centre: float, quantile: float = 0.5
             ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """``loss``'s mean with each element weighted by ``1 + focus`` near ``centre`` (TrainConfig.focus)."""
    element = _pinball(quantile) if loss == "quantile" else _ELEMENT_LOSSES[loss]

    def weighted(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        w = 1.0 + focus * torch.exp(-0.5 * ((t - centre) / FOCUS_WIDTH) ** 2)
        return (w * element(p, t)).sum() / w.sum()
    return weighted


#: TrainConfig.optimizer and TrainConfig.schedule: the names each accepts.
OPTIMIZERS = ("rmsprop", "adamw")
SCHEDULES = ("exponential", "cosine")


def _optimizer(net: nn.Module, cfg: TrainConfig) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler]:
    """The optimizer and learning-rate schedule ``cfg`` names (both stepped once per training step)."""
    if cfg.optimizer == "adamw":
        opt: torch.optim.Optimizer = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    else:
        opt = torch.optim.RMSprop(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    if cfg.schedule == "cosine":
        warm, total = max(1, cfg.steps // 50), cfg.steps

        def factor(step: int) -> float:
            if step < warm:
                return (step + 1) / warm
            return 0.5 * (1.0 + math.cos(math.pi * min(1.0, (step - warm) / max(1, total - warm))))

        return opt, torch.optim.lr_scheduler.LambdaLR(opt, factor)
    return opt, torch.optim.lr_scheduler.ExponentialLR(opt, gamma=1.0 - cfg.lr_decay)


def _pad_to_tiles(x: torch.Tensor, tile: int) -> torch.Tensor:
    """``x`` padded up to a multiple of ``tile`` (whole tiles, or a network's ``input_multiple``) by repeating its
    last row and column, as the SDK pads a frame (``ModelMetadata.pad_multiple``)."""
    h, w = x.shape[-2:]
    return F.pad(x, (0, -w % tile, 0, -h % tile), mode="replicate")


def _scored_tiles(oy: Sequence[int], ox: Sequence[int], n: int, margin: int, tile: int, frame_h: int,
                  frame_w: int) -> np.ndarray:
    """``(B, 1, n, n)`` bool: the tiles of each ``n x n``-tile window (origins ``oy``, ``ox`` in pixels)
    that are scored with ``margin`` tiles of context: all but the outer ``margin`` rings, except on a side
    where the window meets the border of the ``frame_h x frame_w`` frame (those tiles are border tiles in a
    whole frame too). A window that ends at a frame's last whole tile, a partial one beyond it, does not meet
    its border: in the whole frame those tiles see the partial tile's pixels, not padding."""
    out = np.zeros((len(oy), 1, n, n), dtype=bool)
    for b, (y, x) in enumerate(zip(oy, ox)):
        top = 0 if y == 0 else margin
        bottom = n if y + n * tile >= frame_h else n - margin
        left = 0 if x == 0 else margin
        right = n if x + n * tile >= frame_w else n - margin
        out[b, 0, top:bottom, left:right] = True
    return out


def _json_numbers(value: Any) -> Any:
    """``value`` (dicts and lists of scores) with each NaN or infinite float as ``None``: JSON's null."""
    if isinstance(value, dict):
        return {k: _json_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_numbers(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _split_ids(reader: _Sources, cfg: TrainConfig) -> tuple[list[str], list[str], list[str], list[str]]:
    """Training and validation sample ids, and the scenes of each side."""
    by_scene: dict[str, list[str]] = {}
    for s in reader:
        by_scene.setdefault(str(s.meta.get("scene", "?")), []).append(s.id)
    scenes = sorted(by_scene)
    val = list(cfg.val_scenes)
    if not val and cfg.val_split is not None:
        from rtp.capture.scenes import map_names

        val = [s for s in map_names(cfg.val_split, cfg.splits) if s in by_scene]
        if not val:
            log.warning("%s holds none of the %s maps; validating on its last scene instead", cfg.data, cfg.val_split)
    unknown = [v for v in val if v not in by_scene]
    if unknown:
        raise sdk.ParameterError(f"validation scenes {unknown} are not in {cfg.data}; it holds {', '.join(scenes)}",
                                 "val_scenes")
    if not val:
        if len(scenes) < 2:
            # (not the one it holds: a capture names it procedural:N, which the check read as procedural_N only)
            seed = next(k for k in range(1, 100) if f"procedural_{k}" not in scenes and f"procedural:{k}" not in scenes)
            raise DatasetError(
                f"{cfg.data} holds one scene ({scenes[0] if scenes else 'none'}); validation holds out whole scenes, "
                f"so it needs two: capture another into it (rtp capture --scene procedural:{seed} --out "
                f"{shlex.quote(str(cfg.data))} with "
                "the same --size adds the built-in generator's, or --scene another of your files), or, of an engine's "
                "frames, import another level's (rtp import FRAMES --scene LEVEL --out DATA)")
        # the last in the natural order of the names (procedural:10 after procedural:9, not before procedural:2)
        val = [max(scenes, key=sdk.files._natural)]
    train_ids = [i for s in scenes if s not in val for i in by_scene[s]]
    if not train_ids:  # (was an IndexError once the split was loaded)
        key = "val_scenes" if cfg.val_scenes else "val_split"
        raise sdk.ParameterError(f"{key}: every scene of {cfg.data} ({', '.join(scenes)}) is held out for validation; "
                                 "leave at least one to train on", key)
    val_ids = [i for s in val for i in by_scene[s]]
    if cfg.per_scene:
        kept: dict[tuple[str, str], list[str]] = {}
        for i in sorted(train_ids):
            kept.setdefault((reader[i].meta.get("scene", "?"), reader[i].meta.get("profile", "?")), []).append(i)
        first = {i for ids in kept.values() for i in ids[: cfg.per_scene]}
        train_ids = [i for i in train_ids if i in first]
    if cfg.max_samples:
        train_ids = train_ids[: cfg.max_samples]
    train_scenes = sorted(s for s in scenes if s not in val and set(by_scene[s]) & set(train_ids))
    return train_ids, val_ids, train_scenes, sorted(val)


def _make_transform(cfg: TrainConfig, targets: Sequence[np.ndarray], what: str = "training") -> sdk.Transform:
    """The target transform of ``cfg.transform`` with ``mu_Y`` measured on ``targets`` (the training frames')."""
    allv = np.concatenate([y.ravel() for y in targets])
    allv = allv[np.isfinite(allv)]
    if allv.size == 0:
        raise TargetError(f"the {what} targets hold no finite value")
    mu = float(allv.mean())
    if cfg.transform not in ("clamped", "logistic"):
        raise sdk.ParameterError(f"transform: expected clamped or logistic, got {cfg.transform!r}", "transform")
    targets_of = f"the {what} targets" + (f" ({cfg.metric})" if what == "training" else "")
    # (the transform's own refusal spoke of metadata: "transform.mu_y: expected a number in [1e-06, 1e+06] (the mean
    # training target), got 0", of a dataset whose targets are all 0, or "choose mu_y inside [0, 1]", measured)
    try:
        if cfg.transform == "clamped":
            return sdk.Transform.clamped(mu)
        return sdk.Transform.logistic(mu, cfg.logistic_k)
    except sdk.MetadataError as err:  # (the sdk's ranges, one record of them: its message names them)
        key = str(err.key)
        if key.endswith(".mu_y"):
            why = (f"every one is {allv[0]:g}: the data holds no error to learn" if bool((allv == allv[0]).all()) else
                   "a metric whose typical value is not a positive number of that range")
            raise TargetError(f"{targets_of} have mean {mu:g}, which the {cfg.transform} transform divides by (its "
                              f"mu_y): {str(err).split(': ', 1)[-1]}; {why}") from None
        if key.endswith(".k"):
            raise sdk.ParameterError(f"logistic_k: {str(err).split(': ', 1)[-1]} (the logistic transform's growth "
                                     "rate)", "logistic_k") from None
        # (a logistic transform flat over [0, 1] around the measured mean)
        raise sdk.ParameterError(f"logistic_k: {cfg.logistic_k:g} does not fit {targets_of}, of mean {mu:g} (the "
                                 f"transform's mu_y): the logistic transform is then flat over [0, 1] and every "
                                 f"network output would decode to one value: a smaller logistic_k (--k), or transform "
                                 f"clamped", "logistic_k") from None


def _predict_frames(net: Network, xs: Sequence[Frame], tile: int, n: int | None = None) -> list[np.ndarray]:
    """The network's outputs on whole frames (the first ``n`` outputs: the metric's, without auxiliary ones), each
    frame padded as the SDK pads it for the exported model: up to the network's ``input_multiple`` (whole tiles
    for the paper's network). Padded to whole tiles, the fast network's last row or column of partial tiles (a
    1920x1080 frame's, at 16-pixel tiles) and the tiles above it read eight repeated rows the exported model never
    sees: the validation scores and the safety margin were of predictions the model does not make."""
    out = []
    dev = next(net.parameters()).device  # (where the network trains)
    multiple = net.input_multiple or tile
    with torch.inference_mode():
        for x in xs:
            t = torch.from_numpy(x.full())[None].to(dev).to(dtype=torch.float32, memory_format=_layout(dev))
            h, w = t.shape[-2:]
            th, tw = sdk.tile_grid(int(h), int(w), tile)
            y = net(_pad_to_tiles(t, multiple))[0, :n, :th, :tw]
            out.append(y.cpu().numpy())
    return out


def _validate(
    net: Network, val: _Split, t: sdk.Transform, cfg: TrainConfig, worse: float
) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    net.eval()
    preds = _predict_frames(net, val.x, cfg.tile, len(cfg.outputs))
    # (outputs, tiles): one row per output rate, every validation tile along it
    p = np.concatenate([a.reshape(len(a), -1) for a in preds], axis=1)
    g = np.concatenate([t.forward(y).reshape(len(y), -1) for y in val.y], axis=1)
    s = scores(p, g, worse=worse).as_dict()
    net.train()
    return s, p, g


#: An output whose predictions on the validation tiles spread less than this (in the network's
#: (0, 1) output space) is dead; live outputs spread by about 0.1.
DEAD_OUTPUT_STD = 1e-3


def _dead_outputs(pred: np.ndarray, outputs: Sequence[str]) -> list[str]:
    """The outputs whose validation predictions (rows of ``pred``) are one constant."""
    return [r for r, row in zip(outputs, pred) if float(row.std()) < DEAD_OUTPUT_STD]


def _teacher_targets(cfg: TrainConfig, reader: _Sources, tr: _Split, transform: sdk.Transform) -> list[np.ndarray]:
    """The teachers' mean prediction (transformed space, ``cfg.outputs`` rows) on every training
    frame, on the frame's own tiles like the targets. Teachers must predict ``cfg.metric`` on
    ``cfg.tile`` tiles with the student's target transform and every output the student has."""
    teachers = []
    for path in cfg.teachers:
        try:
            t = sdk.load(path, providers=["CPUExecutionProvider"])
        except sdk.RtpError as e:
            raise sdk.ParameterError(f"teachers: {path} is not a model rtp can load: {e}", "teachers") from e
        m = t.metadata
        want, got = transform.to_dict(), m.transform.to_dict()
        same = want.keys() == got.keys() and all(
            np.isclose(want[k], got[k], rtol=1e-5) if isinstance(want[k], float) else want[k] == got[k] for k in want)
        missing = [r for r in cfg.outputs if r not in m.outputs]
        if m.metric != cfg.metric or m.tile_size != cfg.tile or missing or not same:
            raise sdk.ParameterError(
                f"teachers: {path} predicts {m.metric} on {m.tile_size}-pixel tiles, outputs {', '.join(m.outputs)}, "
                f"transform {got}; the student needs {cfg.metric} on {cfg.tile}-pixel tiles, outputs "
                f"{', '.join(cfg.outputs)}, transform {want} (teachers trained on the same data and metric)", "teachers")
        teachers.append((t, [list(m.outputs).index(r) for r in cfg.outputs]))
    out = []
    for k, i in enumerate(tr.ids):
        preds = []
        for t, rows in teachers:
            names = t.metadata.inputs
            x = tr.x[k].full().astype(np.float32) if tuple(names) == tuple(cfg.inputs) else reader[i].inputs(names)
            preds.append(t.predict_raw(x)[rows])
        out.append(np.mean(preds, axis=0).astype(np.float32))
        if out[-1].shape != tr.y[k].shape:
            raise sdk.ParameterError(f"teachers: predictions of shape {out[-1].shape} on {i}, targets {tr.y[k].shape}",
                                     "teachers")
    log.info("distilling %d teacher(s) with weight %g", len(teachers), cfg.distill)
    return out


@torch.no_grad()
def _ema_update(avg: Network, net: Network, decay: float) -> None:
    """``avg <- decay * avg + (1 - decay) * net`` for weights and BatchNorm statistics (the step
    counters are copied). The decay ramps up from 0.1 over the first steps, so early weights fade."""
    for a, b in zip(avg.state_dict().values(), net.state_dict().values()):
        if a.dtype.is_floating_point:
            a.mul_(decay).add_(b, alpha=1.0 - decay)
        else:
            a.copy_(b)


def _layout(dev: torch.device) -> torch.memory_format:
    """The memory layout training keeps the network's weights and inputs in: channels-last on the CPU,
    where torch's oneDNN convolutions run faster so (a whole step of the shipped JNYang recipe 19.1 ms
    against 31.2 on the 2-core machine, the paper's network 68.6 against 105.5: docs/training.md "On a
    GPU"), the same values to float32 round-off; torch's default elsewhere (not measured on a GPU)."""
    return torch.channels_last if dev.type == "cpu" else torch.contiguous_format


@contextlib.contextmanager
def _deterministic(dev: torch.device) -> Any:
    """On CUDA, torch's deterministic algorithms while it lasts (the settings before are restored): cuDNN's
    fastest kernels sum a convolution's gradients in an order that varies from run to run, so a training
    resumed half-way did not end on the model an uninterrupted one did, as it does on the CPU (the
    tests hold both to that). An operation with no deterministic kernel runs anyway, with torch's warning."""
    if dev.type != "cuda":
        yield
        return
    before = (torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark,
              torch.are_deterministic_algorithms_enabled(), torch.is_deterministic_algorithms_warn_only_enabled())
    workspace = os.environ.get("CUBLAS_WORKSPACE_CONFIG")
    os.environ["CUBLAS_WORKSPACE_CONFIG"] = workspace or ":4096:8"  # (what cuBLAS needs to be deterministic)
    torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = True, False
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = before[:2]
        torch.use_deterministic_algorithms(before[2], warn_only=before[3])
        if workspace is None:
            os.environ.pop("CUBLAS_WORKSPACE_CONFIG", None)


#: The seeds torch's generator takes (a signed or an unsigned 64-bit integer).
SEED_RANGE = (-2**63, 2**64 - 1)


def check_config(cfg: TrainConfig) -> TrainConfig:
    """Refuse a configuration :func:`train` cannot run, before any work: every field of its type, then
    the ranges and combinations of the fields (``TrainConfig.from_recipe`` runs this too, so that a
    recipe's ``width: 1`` fails when the recipe is read). What needs the data (a crop larger than the
    frames) is checked once it is loaded. Raises :class:`rtp.sdk.ParameterError` naming the field.
    Returns a copy of ``cfg`` with each field of its type (numpy's numbers as Python's: ``_recipe.normal_fields``),
    the configuration :func:`train` runs."""
    cfg = replace(cfg, **check_fields(cfg))  # every field of its type, before the checks of their ranges below
    try:
        info = metric_info(cfg.metric)  # rtp's own or a plugin's (rtp.metrics.Metric)
    except MetricParameterError as err:
        raise sdk.ParameterError(str(err), "metric") from None
    for name, count in (("steps", cfg.steps), ("batch", cfg.batch), ("crop", cfg.crop), ("val_every", cfg.val_every),
                        ("save_every", cfg.save_every)):
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            # (steps=-5 wrote an untrained checkpoint; batch, crop, val_every or save_every 0 failed in numpy or torch)
            raise sdk.ParameterError(f"{name}: expected an integer >= 1, got {count!r}", name)
    if not SEED_RANGE[0] <= cfg.seed <= SEED_RANGE[1]:
        # (torch.manual_seed's range: 2**70 was an OverflowError once the data had been loaded)
        raise sdk.ParameterError(f"seed: expected an integer in [{SEED_RANGE[0]}, {SEED_RANGE[1]}], got {cfg.seed}", "seed")
    if cfg.tile not in sdk.TILE_SIZES:
        raise sdk.ParameterError(f"tile: expected one of {sdk.TILE_SIZES}, got {cfg.tile!r}", "tile")
    if tuple(cfg.outputs) not in {tuple(o) for o in sdk.OUTPUT_SETS}:
        raise sdk.ParameterError(f"outputs: expected one of {[list(o) for o in sdk.OUTPUT_SETS]}, got {cfg.outputs!r}",
                                 "outputs")
    # (an unknown channel failed as a DatasetError once the data was being read; a repeated one as a
    # MetadataError at the first checkpoint save, steps into the training; none in torch's Conv2d)
    unknown = [c for c in cfg.inputs if c not in sdk.CHANNELS]
    repeated = sorted({c for c in cfg.inputs if cfg.inputs.count(c) > 1}, key=cfg.inputs.index)
    if not cfg.inputs or unknown or repeated:
        got = (f"unknown channel(s) {', '.join(map(repr, unknown))}" if unknown else
               f"{', '.join(repeated)} more than once" if repeated else "none")
        raise sdk.ParameterError(f"inputs: expected one or more distinct channels among {', '.join(sdk.CHANNELS)}, "
                                 f"got {got}", "inputs")
    if cfg.head not in HEADS:
        raise sdk.ParameterError(f"head: expected one of {', '.join(HEADS)}, got {cfg.head!r}", "head")
    for key, value, ok, expected in (
            ("lr", cfg.lr, cfg.lr > 0, "a finite learning rate > 0"),
            ("lr_decay", cfg.lr_decay, cfg.lr_decay >= 0, "a finite decay >= 0"),
            ("weight_decay", cfg.weight_decay, cfg.weight_decay >= 0, "a finite weight decay >= 0"),
            ("logistic_k", cfg.logistic_k, cfg.logistic_k > 0, "a finite growth rate > 0"),
            ("safety_quantile", cfg.safety_quantile,
             cfg.safety_quantile is None or 0.0 <= cfg.safety_quantile < 1.0, "None or a share in [0, 1)"),
            ("default_threshold", cfg.default_threshold,
             cfg.default_threshold is None or info.higher_is_better or cfg.default_threshold >= 0,
             "a finite threshold in metric units, >= 0 for an error metric")):
        if value is not None and not (math.isfinite(value) and ok):
            raise sdk.ParameterError(f"{key}: expected {expected}, got {value}", key)
    if cfg.crop % cfg.tile:
        raise sdk.ParameterError(f"crop ({cfg.crop}) must be a multiple of the tile size ({cfg.tile})", "crop")
    if cfg.splits is not None and cfg.val_split is None and not cfg.val_scenes:  # (recorded and ignored)
        raise sdk.ParameterError(f"splits: read only with val_split (the split of it whose maps are held out), got "
                                 f"splits {cfg.splits} without it: the last scene would be held out and the file "
                                 "ignored; give val_split too, or leave splits out", "splits")
    if cfg.arch not in ARCHS:
        raise sdk.ParameterError(f"arch: expected one of {', '.join(ARCHS)}, got {cfg.arch!r}", "arch")
    pairs = [("normal.x", "normal.y"), ("motion.x", "motion.y"),
             *((c[:-1] + "x", c[:-1] + "y") for c in cfg.inputs if c.endswith((".dx", ".dy")))]
    if cfg.augment and any((a in cfg.inputs) != (b in cfg.inputs) for a, b in pairs):
        raise sdk.ParameterError("augment: transposing a crop needs both normal.x and normal.y (and both motion.x and "
                                 "motion.y, and a .dx plane's .dy) among the inputs, or neither; got "
                                 f"{', '.join(cfg.inputs)}", "augment")
    packed = [c for c in cfg.inputs if c.endswith((".blocks", ".tiles"))]
    if cfg.augment and packed:
        raise sdk.ParameterError(f"augment: {', '.join(packed)} pack one value per pixel of each cell or tile; a "
                                 "transposed crop would put each value on another rate's pixel (a flip keeps them: "
                                 "mirror takes them)", "augment")
    coarse_cells = [c for c in packed if packed_cell(c) > cfg.tile]
    if cfg.mirror and coarse_cells:  # (crops start on the tile grid: one between two cells mirrored them garbled)
        raise sdk.ParameterError(f"mirror: {', '.join(coarse_cells)} mirror by whole {packed_cell(coarse_cells[0])}-"
                                 f"pixel cells, and crops on {cfg.tile}-pixel tiles start between them: expected tile "
                                 f">= {max(packed_cell(c) for c in coarse_cells)} with them, got {cfg.tile}", "mirror")
    if cfg.mirror and cfg.augment:
        raise sdk.ParameterError("mirror: augment's eight symmetries include the mirror; give one of the two", "mirror")
    if cfg.loss not in LOSSES:
        raise sdk.ParameterError(f"loss: expected one of {', '.join(LOSSES)}, got {cfg.loss!r}", "loss")
    if cfg.loss == "quantile" and not 0.0 < cfg.quantile < 1.0:
        raise sdk.ParameterError(f"quantile: expected a number in (0, 1), got {cfg.quantile}", "quantile")
    if not (cfg.focus >= 0.0 and math.isfinite(cfg.focus)):
        raise sdk.ParameterError(f"focus: expected a weight >= 0 (0: off), got {cfg.focus}", "focus")
    if cfg.optimizer not in OPTIMIZERS:
        raise sdk.ParameterError(f"optimizer: expected one of {', '.join(OPTIMIZERS)}, got {cfg.optimizer!r}", "optimizer")
    if cfg.schedule not in SCHEDULES:
        raise sdk.ParameterError(f"schedule: expected one of {', '.join(SCHEDULES)}, got {cfg.schedule!r}", "schedule")
    if cfg.width < 2 or cfg.depth < 0 or cfg.stem not in (1, 2, 4, 8) or cfg.grow not in (1, 2):
        wrong = next(k for k, ok in (("width", cfg.width >= 2), ("depth", cfg.depth >= 0),
                                     ("stem", cfg.stem in (1, 2, 4, 8)), ("grow", cfg.grow in (1, 2))) if not ok)
        raise sdk.ParameterError(f"expected width >= 2, depth >= 0, stem 1, 2, 4 or 8 and grow 1 or 2, got {cfg.width}, "
                                 f"{cfg.depth}, {cfg.stem} and {cfg.grow}", wrong)
    if cfg.arch != "fast":  # (the paper's network has none of these: they were taken and ignored, and recorded)
        for key, default in (("depth", 3), ("stem", 4), ("grow", 1), ("stem_layers", 1)):
            if getattr(cfg, key) != default:
                raise sdk.ParameterError(f"{key}: the fast network's option (the paper's network has its own fixed "
                                         f"layers), got {key} {getattr(cfg, key)} with arch {cfg.arch!r}", key)
    if cfg.arch != "paper" and cfg.head != "paper":  # (the fast network's head was taken and ignored, and recorded)
        raise sdk.ParameterError(f"head: the paper network's option (the fast network's head has no ReLU before its "
                                 f"sigmoid; head_width sets it), got head {cfg.head} with arch {cfg.arch!r}", "head")
    if cfg.max_width and (cfg.grow == 1 or cfg.max_width < cfg.width):
        raise sdk.ParameterError(f"max_width caps grow 2's channels: expected 0 (none), or at least width ({cfg.width}) "
                                 f"with grow 2, got {cfg.max_width} with grow {cfg.grow}", "max_width")
    if cfg.stem_layers not in (1, 2) or (cfg.stem_layers == 2 and min(cfg.stem, cfg.tile) < 2):
        raise sdk.ParameterError(f"stem_layers: expected 1, or 2 with a stem of at least 2, got {cfg.stem_layers} with "
                                 f"stem {cfg.stem}", "stem_layers")
    if cfg.separable and cfg.arch != "fast":
        raise sdk.ParameterError(f"separable: the fast network's option, got arch {cfg.arch!r}", "separable")
    if cfg.separable_tail and cfg.arch != "fast":
        raise sdk.ParameterError(f"separable_tail: the fast network's option, got arch {cfg.arch!r}", "separable_tail")
    if cfg.tail_width and cfg.arch != "fast":
        raise sdk.ParameterError(f"tail_width: the fast network's option, got arch {cfg.arch!r}", "tail_width")
    if cfg.tail_width and (cfg.tail_width < 2 or cfg.depth <= int(math.log2(cfg.tile // min(cfg.stem, cfg.tile)))):
        raise sdk.ParameterError(f"tail_width sets the channels of the blocks at tile resolution: expected 0 (none), "
                                 f"or >= 2 with blocks at tile resolution (depth {cfg.depth} with stem {cfg.stem} and "
                                 f"tile {cfg.tile} has none), got {cfg.tail_width}", "tail_width")
    if cfg.arch == "fast":  # (options of blocks this network has none of built it unchanged, and were recorded)
        pools = int(math.log2(cfg.tile // min(cfg.stem, cfg.tile)))

        def widths(grow: int) -> list[int]:  # the channels of the 3x3 blocks, as FastNet gives them
            return [cfg.tail_width if cfg.tail_width and i >= pools
                    else min(cfg.width * grow ** min(i, pools), cfg.max_width or cfg.width * grow ** pools)
                    for i in range(cfg.depth)]

        if cfg.grow == 2 and widths(2) == widths(1):
            raise sdk.ParameterError(f"grow: 2 doubles the channels of the blocks after a pool below tile resolution, and "
                                     f"this network has none to double (depth {cfg.depth}, stem {cfg.stem}, tile "
                                     f"{cfg.tile}, tail_width {cfg.tail_width}, max_width {cfg.max_width}): expected "
                                     f"grow 1, or more blocks", "grow")
        if cfg.separable_tail and (cfg.separable or cfg.depth <= pools):
            why = ("separable makes every block so already" if cfg.separable else
                   f"depth {cfg.depth} with stem {cfg.stem} and tile {cfg.tile} has no block at tile resolution")
            raise sdk.ParameterError(f"separable_tail: makes the blocks at tile resolution depthwise-separable, and {why}: "
                                     "it would change nothing", "separable_tail")
    if cfg.head_width and cfg.arch != "fast":
        raise sdk.ParameterError(f"head_width: the fast network's option, got arch {cfg.arch!r}", "head_width")
    if cfg.head_width < 0:
        raise sdk.ParameterError(f"head_width: expected 0 (a linear head) or the hidden channels of the head, got "
                                 f"{cfg.head_width}", "head_width")
    if cfg.context_pool and cfg.arch != "fast":
        raise sdk.ParameterError(f"context_pool: the fast network's option, got arch {cfg.arch!r}", "context_pool")
    if cfg.context_pool and (cfg.context_pool < 3 or cfg.context_pool % 2 == 0):
        raise sdk.ParameterError(f"context_pool: expected 0 (none) or an odd window of at least 3 tiles, got "
                                 f"{cfg.context_pool}", "context_pool")
    if cfg.coarse and cfg.arch != "fast":
        raise sdk.ParameterError(f"coarse: the fast network's option, got arch {cfg.arch!r}", "coarse")
    pooled = int(math.log2(cfg.tile // min(cfg.stem, cfg.tile)))
    if cfg.coarse < 0 or (cfg.coarse and (cfg.depth <= pooled or cfg.coarse_width < 2)):
        raise sdk.ParameterError(f"coarse: expected 0 (none), or blocks at twice the tile's scale after a block at tile "
                                 f"resolution (depth {cfg.depth} with stem {cfg.stem} and tile {cfg.tile} needs over "
                                 f"{pooled}) of coarse_width >= 2, got {cfg.coarse} blocks of {cfg.coarse_width}", "coarse")
    if cfg.block_contrast and cfg.arch != "fast":
        raise sdk.ParameterError(f"block_contrast: the fast network's option, got arch {cfg.arch!r}", "block_contrast")
    missing = [c for c in cfg.block_contrast if c not in cfg.inputs]
    if missing or len(set(cfg.block_contrast)) != len(cfg.block_contrast):
        raise sdk.ParameterError(f"block_contrast: expected distinct channels among the inputs "
                                 f"({', '.join(cfg.inputs)}), got {', '.join(cfg.block_contrast)}", "block_contrast")
    if cfg.contrast_cell and not cfg.block_contrast:
        raise sdk.ParameterError("contrast_cell: only with block_contrast (the planes to measure)", "contrast_cell")
    cells = [min(cfg.stem, cfg.tile) * 2 ** i for i in range(8) if min(cfg.stem, cfg.tile) * 2 ** i <= cfg.tile]
    if cfg.contrast_cell and cfg.contrast_cell not in cells:
        raise sdk.ParameterError(f"contrast_cell: expected 0 (the stem's) or one of {', '.join(map(str, cells))} (the "
                                 f"stem or a pooled resolution up to the tile), got {cfg.contrast_cell}", "contrast_cell")
    stored = [c for c in cfg.block_contrast if c.endswith((".blocks", ".tiles"))]
    if stored and (len(stored) != len(cfg.block_contrast) or len({c.rsplit(".", 1)[1] for c in stored}) != 1
                   or list(cfg.inputs[len(cfg.inputs) - len(stored):]) != sorted(stored, key=cfg.inputs.index)):
        raise sdk.ParameterError(f"block_contrast: .blocks or .tiles planes ({', '.join(stored)}) are read as stored "
                                 "variances, by the contrast alone: name only .blocks planes or only .tiles planes, and "
                                 "put them last among the inputs", "block_contrast")
    if stored and stored[0].endswith(".tiles") and not cfg.tile == cfg.contrast_cell == sdk.BLOCK_TILE:
        raise sdk.ParameterError(f"block_contrast: .tiles planes summarise {sdk.BLOCK_TILE}-pixel tiles: expected tile "
                                 f"{sdk.BLOCK_TILE} and contrast_cell {sdk.BLOCK_TILE}, got tile {cfg.tile} and "
                                 f"contrast_cell {cfg.contrast_cell}", "block_contrast")
    if cfg.contrast_max and (not cfg.block_contrast or (cfg.contrast_cell or min(cfg.stem, cfg.tile)) <= 4):
        raise sdk.ParameterError("contrast_max: only with block_contrast and a contrast_cell over 4 pixels (the worst "
                                 "4x4 cell of each larger one)", "contrast_max")
    if cfg.block_contrast and min(cfg.stem, cfg.tile) < 2:
        raise sdk.ParameterError(f"block_contrast: needs a stem of at least 2 pixels, got {min(cfg.stem, cfg.tile)}",
                                 "block_contrast")
    if cfg.energy_norm and cfg.arch != "fast":
        raise sdk.ParameterError(f"energy_norm: the fast network's option, got arch {cfg.arch!r}", "energy_norm")
    if not 0.0 < cfg.distill <= 1.0:
        raise sdk.ParameterError(f"distill: expected a weight in (0, 1], got {cfg.distill}", "distill")
    _make_transform(cfg, [np.ones(1, np.float32)])  # (a transform it cannot fit, refused now, on a stand-in target)
    for path in cfg.teachers:  # (each loaded only once the training data is; a file that is no model refused now)
        try:
            sdk.load(path, providers=["CPUExecutionProvider"])
        except sdk.RtpError as e:
            raise sdk.ParameterError(f"teachers: {path} is not a model rtp can load: {e}", "teachers") from e
    bad = [m for m in cfg.aux_metrics if m not in known_metrics() or m == cfg.metric]
    if bad or len(set(cfg.aux_metrics)) != len(cfg.aux_metrics):
        raise sdk.ParameterError(f"aux_metrics: expected distinct metrics among {', '.join(known_metrics())} other than "
                                 f"{cfg.metric}, got {', '.join(cfg.aux_metrics)}", "aux_metrics")
    if cfg.aux_metrics and cfg.arch != "fast":
        raise sdk.ParameterError(f"aux_metrics: the fast network's option, got arch {cfg.arch!r}", "aux_metrics")
    if cfg.aux_metrics and (cfg.augment or cfg.mirror):
        raise sdk.ParameterError(f"aux_metrics and {'augment' if cfg.augment else 'mirror'} cannot be combined (the "
                                 "auxiliary targets are not transformed with the crop)", "aux_metrics")
    if not (cfg.aux_weight > 0.0 and math.isfinite(cfg.aux_weight)):
        raise sdk.ParameterError(f"aux_weight: expected a weight > 0, got {cfg.aux_weight}", "aux_weight")
    if not 0.0 <= cfg.ema < 1.0:
        raise sdk.ParameterError(f"ema: expected a decay in [0, 1) (0: off), got {cfg.ema}", "ema")
    twice = sorted({v for v in cfg.val_scenes if cfg.val_scenes.count(v) > 1}, key=cfg.val_scenes.index)
    if twice:  # (each of its samples was validated twice, and val_samples and val_scenes recorded so)
        raise sdk.ParameterError(f"val_scenes: expected distinct scene names, got {', '.join(twice)} more than once",
                                 "val_scenes")
    if cfg.max_samples is not None and cfg.max_samples < 1:  # (-1 left out the last sample, 0 kept them all)
        raise sdk.ParameterError(f"max_samples: expected None (every sample) or at least 1 training sample, got "
                                 f"{cfg.max_samples}", "max_samples")
    if cfg.per_scene is not None and cfg.per_scene < 1:
        raise sdk.ParameterError(f"per_scene: expected at least 1 sample per map and motion profile, got {cfg.per_scene}",
                                 "per_scene")
    if cfg.context < 0 or cfg.context % cfg.tile:
        raise sdk.ParameterError(f"context must be a multiple of the tile size ({cfg.tile}) and >= 0, got {cfg.context}",
                                 "context")
    if cfg.context and cfg.augment:
        raise sdk.ParameterError("context and augment cannot be combined (the scored region would need transforming too)",
                                 "context")
    with torch.device("meta"):  # the network itself (its size included), before any data is read; allocates nothing
        _network(cfg)
    dev = resolve_device(cfg.device)
    need = step_bytes(cfg)
    if dev.type == "cuda":  # the step's activations live on the GPU; its crops are cut in host memory
        total = torch.cuda.get_device_properties(dev).total_memory
        if need > total:
            raise sdk.ParameterError(f"batch: {cfg.batch} crops of {cfg.crop + 2 * cfg.context} pixels take about "
                                     f"{need / 2**30:.1f} GiB in a training step, more than the {total / 2**30:.1f} GiB "
                                     f"of {device_name(dev)}: lower batch or crop", "batch")
        need = _crop_bytes(cfg)
    kept = ("the crops, cut here for the GPU" if dev.type == "cuda" else
            f"what autograd keeps of the {cfg.arch} network's activations, and the crops")
    check_memory(need, f"{cfg.batch} crops of {cfg.crop + 2 * cfg.context} pixels take about {need / 2**30:.1f} GiB in "
                       f"a training step ({kept})",
                 "batch", "of memory: lower batch or crop", job="the training", logger=log)
    return cfg


def _check_fits_in_memory(reader: _Sources, train_ids: Sequence[str], val_ids: Sequence[str], cfg: TrainConfig) -> None:
    """Refuse a dataset whose input planes cannot all be held in memory before they are read: its first
    sample's planes as training keeps them (float16, ``.blocks`` and ``.tiles`` packed), times the
    samples (one size for all, as checked once they are read). Past the memory available now: a warning."""
    ids = [*train_ids, *val_ids]
    if not ids:
        return
    one = Frame(reader[ids[0]].inputs(cfg.inputs), cfg.inputs).nbytes
    need = one * len(ids)
    check_memory(need, f"the {len(ids):,} samples' {len(cfg.inputs)} input planes take about {need / 2**30:.1f} GiB in "
                       f"memory (training holds them all)",
                 "max_samples", "of memory: train on fewer (max_samples, per_scene) or fewer planes", job="the training",
                 logger=log)


def _crop_bytes(cfg: TrainConfig) -> int:
    """Bytes of a step's batch of crops in host memory: cut as float16, then float32 (on the CPU)."""
    side = cfg.crop + 2 * cfg.context
    return cfg.batch * len(cfg.inputs) * side * side * (2 + 4)


def step_bytes(cfg: TrainConfig) -> int:
    """Bytes a training step of ``cfg`` holds for its batch: the crops (stored as float16, then float32)
    and what autograd saves of the network's forward pass over them for the backward pass. A batch and
    crop that leave a BatchNorm layer one value per channel (a single 16-pixel crop through the fast
    network) cannot train at all: :class:`~rtp.sdk.ParameterError` naming ``batch``.

    The forward pass runs on two crops (one for a batch of one) on torch's ``meta`` device, which
    allocates nothing, with a saved-tensors hook adding up what each operation keeps; scaled to the
    batch. It is a slight underestimate of what a real step adds to the process's peak memory
    (64-pixel crops, batches of 1,000 and 8,000 against 8: the paper's network 1,562 MiB estimated,
    1,637 MiB measured; the fast one 1,955 and 2,284), so refusing past it refuses nothing that would
    have fitted. A network with an operation torch cannot run on ``meta`` is counted by its crops
    alone, with a warning that says so.
    """
    side = cfg.crop + 2 * cfg.context
    crops = _crop_bytes(cfg) // cfg.batch
    n = min(cfg.batch, 2)  # (BatchNorm refuses a batch of one 1x1 map, as it would in training)
    with torch.device("meta"):
        net = _network(cfg).train()
        x = torch.empty(n, len(cfg.inputs), side, side)
    weights = {id(p) for p in net.parameters()}
    saved: dict[int, int] = {}  # storage -> bytes: a tensor saved by two operations (or in place) is held once

    def pack(t: torch.Tensor) -> torch.Tensor:
        if id(t) not in weights:  # (the weights are kept once, not per crop)
            storage = t.untyped_storage()
            saved[storage._cdata] = storage.nbytes()
        return t

    try:
        with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
            net(x)
    except ValueError as err:  # torch's BatchNorm: "Expected more than 1 value per channel when training"
        raise sdk.ParameterError(f"batch: {cfg.batch} crop{'s' if cfg.batch > 1 else ''} of {side} pixels "
                                 f"leave{'' if cfg.batch > 1 else 's'} a "
                                 f"BatchNorm layer of the {cfg.arch} network one value per channel, which it cannot "
                                 f"normalise ({err}): a larger batch or crop", "batch") from err
    except (NotImplementedError, RuntimeError) as err:
        # An operation torch cannot run on meta (no meta kernel, or one that reads values): every network
        # rtp.train.model builds measures (each packaged recipe, each metric), so this is a changed or
        # added layer. The activations are then unknown and left out, and the user is told so.
        log.warning("the activations of the %s network could not be measured on torch's meta device (%s): the "
                    "memory check of a training step counts the crops only", cfg.arch, err)
        return cfg.batch * crops
    return cfg.batch * crops + cfg.batch * sum(saved.values()) // n


def _network(cfg: TrainConfig) -> Network:
    """The untrained network ``cfg`` describes (its outputs: the metric's rates, then each auxiliary metric's)."""
    return build_network(cfg.arch, len(cfg.inputs), len(cfg.outputs) * (1 + len(cfg.aux_metrics)), cfg.tile,
                         width=cfg.width, head=cfg.head, depth=cfg.depth, stem=cfg.stem, grow=cfg.grow,
                         stem_layers=cfg.stem_layers, energy_norm=cfg.energy_norm, max_width=cfg.max_width,
                         separable=cfg.separable, head_width=cfg.head_width, context_pool=cfg.context_pool,
                         block_contrast=tuple(cfg.inputs.index(c) for c in cfg.block_contrast),
                         contrast_cell=cfg.contrast_cell, separable_tail=cfg.separable_tail,
                         tail_width=cfg.tail_width, contrast_max=cfg.contrast_max,
                         contrast_stored=bool(cfg.block_contrast) and cfg.block_contrast[0].endswith((".blocks", ".tiles")),
                         contrast_tiles=bool(cfg.block_contrast) and cfg.block_contrast[0].endswith(".tiles"),
                         coarse=cfg.coarse, coarse_width=cfg.coarse_width)


def train(cfg: TrainConfig, progress: Callable[[int, int, float], None] | None = None, *,
          loading: Callable[[int, int], None] | None = None) -> TrainResult:
    """Train (or resume) a model as ``cfg`` says and write the checkpoint to ``cfg.out``.

    ``progress(step, steps, loss)`` is called as steps complete; before the first, the samples are
    read into memory (a few minutes for the shipped recipe's 1,224): ``loading(read, samples)`` is
    called as each is read, training and validation samples together.

    While it runs it holds the checkpoint's writer lock (``.NAME.rtp-writer.lock`` beside it, removed
    at the end): a second training into the same ``out`` would resume from the same checkpoint and the
    two would save over each other, so it is refused (:class:`~rtp.train.checkpoint.CheckpointError`).
    """
    if not isinstance(cfg, TrainConfig):
        raise sdk.ParameterError(f"train: expected a TrainConfig, got {type(cfg).__name__}")
    cfg = check_config(cfg)  # (its fields as the types they are read as)
    # What the first save or the optimizer would refuse, now rather than 250 steps of training later.
    out = check_output(cfg.out, what="out")
    made = [d for d in (out.parent, *out.parent.parents) if not d.exists()]  # (the folders the lock needs made)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with writer_lock(out.parent, "rtp train", lambda holder: ckpt.CheckpointError(
                f"{out} is being written by another training ({holder}): wait for it to end, or train into another "
                f"file"), name=f".{out.name}{LOCK_NAME}", remove=True):
            with _deterministic(resolve_device(cfg.device)):
                return _train(cfg, progress, loading)
    finally:
        for d in made:  # a training that failed before its first save leaves no empty folders behind
            with contextlib.suppress(OSError):
                d.rmdir()


def _resumable(out: Path) -> ckpt.Checkpoint:
    """The checkpoint at ``out``, which a training into ``out`` resumes: refused if it is none or holds no training
    state (its configuration and steps are compared once the samples, part of it, are known)."""
    prev = ckpt.load(out)
    if not prev.training:
        raise ckpt.CheckpointError(f"{out} exists and holds a model without its training state (saved from Python "
                                   "without one, or exported from elsewhere): nothing to resume; choose another "
                                   "output path or delete it")
    return prev


def _check_tile_pools_targets(cfg: TrainConfig, sources: _Sources) -> None:
    """Refuse, before any sample is read, a tile that is no multiple of a dataset's stored base tile (the targets are
    pooled from whole base tiles: ``--tile 2`` on ``rtp targets``' 4-pixel tiles failed on the first sample's targets
    with a TargetError that said nothing of which tiles would do)."""
    for folder, targets in zip(sources.folders, sources.stores):
        base = targets.base_tile
        if cfg.tile % base:
            fits = [t for t in sdk.TILE_SIZES if t % base == 0]
            raise sdk.ParameterError(f"tile: the targets of {folder} are stored per {base}-pixel tile (rtp targets) and a "
                                     f"model's tile pools whole ones: expected {', '.join(map(str, fits))}, got {cfg.tile}",
                                     "tile")


def _warn_other_plugin_definition(cfg: TrainConfig, stored: Any) -> None:
    """Warn where the targets of a plugin metric were computed by another definition of it (``params`` or pooling:
    the plugin's version 1, version 2 installed now) and the model would take its default threshold from the
    installed one: the model learns the stored targets and records their definition
    (``provenance.target_parameters``), but the threshold is the installed definition's, which may be in other
    units; the stored definition records none to take instead. A ``default_threshold`` given is taken as is."""
    if cfg.default_threshold is not None or cfg.metric in sdk.METRICS or not isinstance(stored, dict) \
            or "plugin" not in stored:
        return
    own = metric_plugins().get(cfg.metric)
    if own is None:
        return
    installed = {"plugin": dict(own.params), "pooling": own.pooling}
    keys = [k for k in ("plugin", "pooling") if k in stored]
    if {k: stored[k] for k in keys} == {k: installed[k] for k in keys}:
        return
    log.warning(
        "the %s targets of %s were computed by another definition of the plugin metric (%s) than the one installed "
        "(%s): the model learns them and records their definition, but takes its default_threshold, %g, from the "
        "installed plugin, which may be in the other definition's units (and centres --focus on it): give the "
        "threshold for these targets (rtp train --threshold, a recipe's default_threshold), or compute the targets "
        "again with the installed plugin (in a copy of the dataset: `rtp targets COPY --metrics %s`)",
        cfg.metric, cfg.data, {k: stored[k] for k in keys}, {k: installed[k] for k in keys}, own.default_threshold,
        cfg.metric,
    )


def _train(cfg: TrainConfig, progress: Callable[[int, int, float], None] | None,
           loading: Callable[[int, int], None] | None = None) -> TrainResult:
    out = Path(cfg.out)
    # a file there that cannot be resumed, refused before the samples are read (minutes, for the shipped recipe)
    prev = _resumable(out) if out.is_file() else None
    loss_fn = _LOSSES[cfg.loss] if cfg.loss != "quantile" else _mean_pinball(cfg.quantile)
    aux_loss_fn = loss_fn  # the auxiliary metrics' loss: the same, without focus (their thresholds differ)
    reader = store = _Sources(cfg.data, cfg.metric, cfg.aux_metrics)
    _check_tile_pools_targets(cfg, store)
    _warn_other_plugin_definition(cfg, store.metrics.get(cfg.metric))
    train_ids, val_ids, train_scenes, val_scenes = _split_ids(reader, cfg)
    _check_fits_in_memory(reader, train_ids, val_ids, cfg)
    log.info("loading %d training and %d validation samples", len(train_ids), len(val_ids))
    read, samples = 0, len(train_ids) + len(val_ids)

    def one_read() -> None:
        nonlocal read
        read += 1
        if loading is not None:
            loading(read, samples)

    start = time.perf_counter()
    tr, va = _Split(reader, store, train_ids, cfg, one_read), _Split(reader, store, val_ids, cfg, one_read)
    h, w = tr.x[0].shape[-2:]
    other = next(((i, f.shape) for i, f in zip((*tr.ids, *va.ids), (*tr.x, *va.x)) if f.shape[-2:] != (h, w)), None)
    if other is not None:
        raise DatasetError(f"sample {other[0]} is {other[1][2]}x{other[1][1]}, the first training sample {w}x{h}: "
                           f"capture the datasets of one training run at one size")
    log.info("%.1f GB of input planes in memory, read in %.1f s", sum(f.nbytes for f in (*tr.x, *va.x)) / 1e9,
             time.perf_counter() - start)
    full_h, full_w = (h // cfg.tile) * cfg.tile, (w // cfg.tile) * cfg.tile
    if min(full_h, full_w) < cfg.tile:  # (no crop fits: it said "a context of at most -16 fits", of no context given)
        smaller = [t for t in sdk.TILE_SIZES if t <= min(h, w)]
        raise sdk.ParameterError(f"tile: the frames ({w}x{h}) hold no whole {cfg.tile}-pixel tile to crop; expected frames "
                                 f"of at least {cfg.tile}x{cfg.tile}" + (f", or a tile of {', '.join(map(str, smaller))}"
                                                                         if smaller else ""), "tile")
    if cfg.crop + 2 * cfg.context > min(full_h, full_w):
        what = f"crop ({cfg.crop})" if not cfg.context else f"crop + 2 x context ({cfg.crop + 2 * cfg.context})"
        # (what fits, said: a recipe without a crop took the default, 128, and the message named a crop nobody gave)
        room = min(full_h, full_w) - 2 * cfg.context
        fits = (f"a crop of at most {room} fits" + (f" ({cfg.crop} is the default)" if cfg.crop == TrainConfig.crop else "")
                if room >= cfg.tile else
                f"a context of at most {(min(full_h, full_w) - cfg.tile) // 2 // cfg.tile * cfg.tile} fits")
        raise sdk.ParameterError(f"{what} is larger than the frames ({w}x{h}): {fits}",
                                 "context" if cfg.context else "crop")

    transform = _make_transform(cfg, tr.y)
    aux_transforms = [_make_transform(cfg, [a[k] for a in tr.aux], f"{m} (aux_metrics)")
                      for k, m in enumerate(cfg.aux_metrics)]
    threshold = cfg.default_threshold if cfg.default_threshold is not None else metric_info(cfg.metric).default_threshold
    if cfg.focus:  # the band's centre: the default threshold in transformed space
        centre = float(tt.forward(torch.tensor([float(threshold)], dtype=torch.float64), transform)[0])
        loss_fn = _focused(cfg.loss, cfg.focus, centre, cfg.quantile)
    soft = _teacher_targets(cfg, reader, tr, transform) if cfg.teachers else None
    higher = metric_info(cfg.metric).higher_is_better
    worse = 1.0 if transform.increasing != higher else -1.0
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    n_out = len(cfg.outputs)
    dev = resolve_device(cfg.device)
    log.info("training on %s", device_name(dev))  # (what auto chose)
    # (initialised on the CPU first: a seed gives the same weights on every device)
    net = _network(cfg).to(dev)
    net.to(memory_format=_layout(dev))  # type: ignore[call-overload]  # (torch's stub lacks the keyword Module.to takes)
    # with ema: `net` trains, `avg` (its moving average) is validated and saved
    avg = copy.deepcopy(net) if cfg.ema else net
    opt, sched = _optimizer(net, cfg)
    step, history = 0, []
    owed_loss: float | None = None  # the loss of a resumed step whose validation an interrupt kept from the history
    config_key = {k: getattr(cfg, k) for k in _RESUME_KEYS}
    if cfg.per_scene:  # checkpoints from before the option hold no "per_scene"
        config_key["per_scene"] = cfg.per_scene
    if cfg.head != "paper":  # checkpoints from before the option compare equal to the paper head
        config_key["head"] = cfg.head
    if cfg.arch != "paper":  # likewise for the architecture
        config_key.update(arch=cfg.arch, depth=cfg.depth)
        if cfg.stem != 4:
            config_key["stem"] = cfg.stem
        if cfg.grow != 1:
            config_key["grow"] = cfg.grow
        if cfg.max_width:
            config_key["max_width"] = cfg.max_width
        if cfg.separable:
            config_key["separable"] = True
        if cfg.separable_tail:
            config_key["separable_tail"] = True
        if cfg.tail_width:
            config_key["tail_width"] = cfg.tail_width
        if cfg.head_width:
            config_key["head_width"] = cfg.head_width
        if cfg.context_pool:
            config_key["context_pool"] = cfg.context_pool
        if cfg.coarse:
            config_key.update(coarse=cfg.coarse, coarse_width=cfg.coarse_width)
        if cfg.block_contrast:
            config_key["block_contrast"] = list(cfg.block_contrast)
        if cfg.contrast_cell:
            config_key["contrast_cell"] = cfg.contrast_cell
        if cfg.contrast_max:
            config_key["contrast_max"] = True
        if cfg.stem_layers != 1:
            config_key["stem_layers"] = cfg.stem_layers
        if cfg.energy_norm:
            config_key["energy_norm"] = True
    if cfg.augment:
        config_key["augment"] = True
    if cfg.mirror:
        config_key["mirror"] = True
    if cfg.context:  # likewise: checkpoints from before the option read no context
        config_key["context"] = cfg.context
    if cfg.loss != "l1":  # likewise: checkpoints from before the option trained with L1
        config_key["loss"] = cfg.loss
    if cfg.loss == "quantile":
        config_key["quantile"] = cfg.quantile
    if cfg.focus:
        config_key["focus"] = cfg.focus
        if threshold != metric_info(cfg.metric).default_threshold:  # the focus band's centre (a resume with another
            config_key["default_threshold"] = float(threshold)       # --threshold trained another loss, silently)
    if cfg.ema:
        config_key["ema"] = cfg.ema
    if cfg.optimizer != "rmsprop":  # likewise: checkpoints from before the options used the paper's
        config_key["optimizer"] = cfg.optimizer
    if cfg.schedule != "exponential":  # a cosine's length is part of it: resuming with other steps is another run
        config_key.update(schedule=cfg.schedule, schedule_steps=cfg.steps)
    if cfg.aux_metrics:
        config_key.update(aux_metrics=list(cfg.aux_metrics), aux_weight=cfg.aux_weight)
    if cfg.teachers:  # the teachers by content: a file replaced under the same name is another run
        config_key.update(distill=cfg.distill, teachers=[hashlib.sha256(Path(t).read_bytes()).hexdigest()
                                                          for t in cfg.teachers])
    if cfg.val_split is not None:  # likewise: only a split-held-out validation records its split
        config_key["val_split"] = cfg.val_split
    # The samples themselves: a dataset grown since (more --per-scene) is another training run.
    config_key["samples"] = {"train": len(train_ids), "val": len(val_ids), "sha256": hashlib.sha256(
        json.dumps([train_ids, val_ids]).encode()).hexdigest()}
    config_key = json.loads(json.dumps(config_key))
    if prev is not None and prev.training:
        state = prev.training

        def unresumable(why: str) -> ckpt.CheckpointError:
            return ckpt.CheckpointError(f"{out}: its training state cannot be resumed ({why}); the file was damaged or "
                                        "edited: delete it to train afresh, or export the model it holds (rtp-export)")

        before = state.get("config") or {}
        if not isinstance(before, dict):  # (an AttributeError from the comparison below)
            raise unresumable(f"config: expected a mapping, got {type(before).__name__}")
        if cfg.arch != "paper":  # (a fast training begun with a head, which it never read, is this run: it resumes)
            before = {k: v for k, v in before.items() if k != "head"}
        if before.get("data") != config_key["data"] and _same_folders(before.get("data"), config_key["data"]):
            before = {**before, "data": config_key["data"]}  # ('data/train/' resuming 'data/train' was refused)
        if before != config_key:
            diff = sorted(k for k in set(before) | set(config_key) if before.get(k) != config_key.get(k))
            raise sdk.ParameterError(f"{out} exists and was trained with another configuration (differs in: {', '.join(diff)}); "
                               "choose another output path or delete it")
        try:
            avg.load_state_dict(state["full_weights"] if cfg.aux_metrics else prev.net.state_dict())
            if cfg.ema:
                net.load_state_dict(state["raw_weights"])
            opt.load_state_dict(state["optimizer"])
            sched.load_state_dict(state["scheduler"])
            gen.set_state(state["generator"])
            step, history = int(state["step"]), list(json.loads(state["history"]))
            if step < 0:
                raise ValueError(f"step {step}")
            # (each entry is read for its step and loss: one that is no mapping, or a loss that is no number, was an
            # AttributeError or ValueError from the lines below, or at the first interrupt)
            if not all(isinstance(e, dict) and isinstance(e.get("step"), int) for e in history):
                raise ValueError("history: expected a list of mappings, each with its step")
            last = history[-1] if history else {}
            last_loss = last.get("train_loss", last.get("train_l1"))  # train_l1: checkpoints from before --loss
            if last_loss is not None:
                last_loss = float(last_loss)
            owed = state.get("pending_validation")  # (an interrupt kept step's validation from the history)
            if owed is not None:
                owed_loss = float(owed["train_loss"])
        except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, IndexError) as exc:
            raise unresumable(f"{type(exc).__name__}: {exc}") from exc
        if step > cfg.steps:
            raise sdk.ParameterError(f"steps: {out} holds step {step}, past this run's {cfg.steps}: give --steps {step} "
                                     "or more to go on training it, or another output path", "steps")
        log.info("resuming %s at step %d", out, step)
        if owed_loss is not None:  # (the step's own loss, its validation not yet in the history)
            last_loss = owed_loss
        if progress and last_loss is not None:  # a resumed run's bar starts where it stopped
            progress(step, cfg.steps, float(last_loss))
    weber = store.metrics.get(cfg.metric, {}).get("weber_l")
    saved_step = step  # the step the checkpoint on disk holds (0: none)

    def metadata(safety: float, extra: dict[str, Any]) -> dict[str, Any]:
        return {
            "metric": cfg.metric,
            "higher_is_better": metric_info(cfg.metric).higher_is_better,  # (a plugin's metric: the SDK knows it not)
            "transform": transform.to_dict(),
            "safety": safety,
            "tile_size": cfg.tile,
            "inputs": list(cfg.inputs),
            "outputs": list(cfg.outputs),
            "default_threshold": cfg.default_threshold
            if cfg.default_threshold is not None
            else metric_info(cfg.metric).default_threshold,
            "weber_l": weber if cfg.metric.startswith("jn") else None,
            "provenance": {
                "data": str(cfg.data),
                "train_scenes": train_scenes,
                "val_scenes": val_scenes,
                "train_samples": len(train_ids),
                **({"per_scene": cfg.per_scene} if cfg.per_scene else {}),
                "val_samples": len(val_ids),
                "resolution": [int(w), int(h)],
                "target_parameters": store.metrics.get(cfg.metric, {}),
                "steps": step,
                "seed": cfg.seed,
                **({"recipe": cfg.recipe} if cfg.recipe else {}),
                "versions": {"rtp": str(sdk.__version__), "torch": str(torch.__version__),
                             "python": platform.python_version()},
                "device": device_name(dev),
                **extra,
            },
        }

    def diverged(what: str) -> TrainingDivergedError:
        kept = (f"{out} keeps step {saved_step}'s weights, where it was still finite" if saved_step
                else f"no checkpoint was written to {out}")
        return TrainingDivergedError(
            f"the training diverged: {what} at step {step}, with learning rate {cfg.lr:g}; {kept}. Train again to "
            "another --out with a lower --lr (resuming this one would diverge the same way), and check that the "
            "dataset's input planes are finite")

    def save(done: bool, safety: float = 0.0, extra: dict[str, Any] | None = None,
             generator: torch.Tensor | None = None, pending: float | None = None) -> None:
        nonlocal saved_step
        saved = keep_outputs(avg, n_out) if cfg.aux_metrics else avg  # type: ignore[arg-type]
        bad = next((k for k, v in {**net.state_dict(), **avg.state_dict()}.items()
                    if v.is_floating_point() and not bool(torch.isfinite(v).all())), None)
        if bad is not None:  # (the last finite checkpoint stays: a diverged one would replace it)
            raise diverged(f"the weights ({bad}) are not finite")
        ckpt.save(out, saved, metadata(safety, extra or {}), training={
            "config": config_key, "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
            "generator": gen.get_state() if generator is None else generator, "step": step,
            "history": json.dumps(history), "done": done,
            **({"raw_weights": net.state_dict()} if cfg.ema else {}),
            **({"full_weights": avg.state_dict()} if cfg.aux_metrics else {}),
            **({"pending_validation": {"train_loss": pending}} if pending is not None else {}),
        })
        saved_step = step

    n_tiles = (cfg.crop + 2 * cfg.context) // cfg.tile  # the window read, in tiles
    margin = cfg.context // cfg.tile
    if step == 0:  # the untrained network's score, the reference every later validation improves on
        s0, _, _ = _validate(avg, va, transform, cfg, worse)
        history.append({"step": 0, "val": s0})
    elif owed_loss is not None:  # the validation an interrupt kept from the history: what the uninterrupted run made
        s, _, _ = _validate(avg, va, transform, cfg, worse)
        history.append({"step": step, "train_loss": owed_loss, "val": s})
        log.info("step %d: train %s %.4f, val MAE %.4f, R2 %.3f", step, cfg.loss, owed_loss, s["mae"], s["r2"])
    net.train()
    # Ctrl-C (or SIGTERM) between two saves keeps the steps done: the state at the last step boundary is saved
    # (the crop sampler as it was when the interrupted step began), unless the interrupt landed while the
    # optimizer, the schedule and the average were being updated, where no consistent state exists until the step
    # ends (the last periodic checkpoint stays). A resumed run still reproduces an uninterrupted one exactly: its
    # weights, and its history too (a validation the interrupt cut short is made when it resumes). The final
    # validation and calibration are covered too: an interrupt there keeps the last step. A step's forward pass moves
    # the BatchNorm running statistics before its weights are updated: those of the step boundary are kept with it
    # (saved as the forward pass had left them, the resumed run's redo of that step counted its batch twice).

    def buffers_now() -> dict[str, torch.Tensor]:
        return {k: b.detach().clone() for k, b in net.named_buffers()}

    boundary_gen, boundary_loss, boundary_buffers, updating = gen.get_state(), owed_loss, buffers_now(), False
    try:
        while step < cfg.steps:
            idx = torch.randint(len(tr.x), (cfg.batch,), generator=gen).tolist()
            oy = (torch.randint(full_h // cfg.tile - n_tiles + 1, (cfg.batch,), generator=gen) * cfg.tile).tolist()
            ox = (torch.randint(full_w // cfg.tile - n_tiles + 1, (cfg.batch,), generator=gen) * cfg.tile).tolist()
            side = cfg.crop + 2 * cfg.context
            xb = crop_batch([tr.x[i] for i in idx], oy, ox, side)
            yb = np.stack([
                tr.y[i][:, y // cfg.tile : y // cfg.tile + n_tiles, x // cfg.tile : x // cfg.tile + n_tiles]
                for i, y, x in zip(idx, oy, ox)
            ])
            if cfg.augment or cfg.mirror:  # SYMMETRIES[1] is the left-right mirror; with context the window mirrors whole
                xb_raw, sym = xb, torch.randint(len(SYMMETRIES) if cfg.augment else 2, (cfg.batch,), generator=gen).tolist()
                xb, yb = augment_batch(xb, yb, cfg.inputs, cfg.outputs, sym)
            target = tt.forward(torch.from_numpy(yb.astype(np.float64)), transform).float()
            target = torch.nan_to_num(target, nan=1.0).to(dev)
            if soft is not None:  # distillation: where the target is known, mix in the teachers' mean
                sb = torch.from_numpy(np.stack([
                    soft[i][:, y // cfg.tile : y // cfg.tile + n_tiles, x // cfg.tile : x // cfg.tile + n_tiles]
                    for i, y, x in zip(idx, oy, ox)]))
                if cfg.augment or cfg.mirror:
                    sb = torch.from_numpy(augment_batch(xb_raw, sb.numpy(), cfg.inputs, cfg.outputs, sym)[1].copy())
                known = torch.from_numpy(np.isfinite(yb)).to(dev)
                target = torch.where(known, (1.0 - cfg.distill) * target + cfg.distill * sb.to(dev), target)
            # (float16 to the device, then float32 there, in the layout the network is in, in one pass: torch converts
            # several times faster than numpy's astype, which took a quarter of a CPU step; half the bytes cross to a GPU)
            out_all = net(torch.from_numpy(xb).to(dev).to(dtype=torch.float32, memory_format=_layout(dev)))
            pred = out_all[:, :n_out]
            scored = None
            if margin:  # (the tiles scored in each window, moved with it when it was mirrored)
                mask = _scored_tiles(oy, ox, n_tiles, margin, cfg.tile, int(h), int(w))  # (the frame's own border)
                if cfg.augment or cfg.mirror:
                    mask = np.stack([move_tiles(m, s) for m, s in zip(mask, sym)])
                scored = torch.from_numpy(np.ascontiguousarray(mask)).to(dev).expand_as(pred)
            loss = loss_fn(pred[scored], target[scored]) if scored is not None else loss_fn(pred, target)
            if cfg.aux_metrics:  # multi-task: each auxiliary metric's outputs against its own transformed targets
                aux_losses = []
                for k, at in enumerate(aux_transforms):
                    ab = np.stack([
                        tr.aux[i][k][:, y // cfg.tile : y // cfg.tile + n_tiles, x // cfg.tile : x // cfg.tile + n_tiles]
                        for i, y, x in zip(idx, oy, ox)])
                    atgt = torch.nan_to_num(tt.forward(torch.from_numpy(ab.astype(np.float64)), at).float(), nan=1.0).to(dev)
                    ap = out_all[:, n_out * (k + 1) : n_out * (k + 2)]
                    aux_losses.append(aux_loss_fn(ap[scored], atgt[scored]) if scored is not None else aux_loss_fn(ap, atgt))
                loss = loss + cfg.aux_weight * torch.stack(aux_losses).mean()
            loss_value = loss.item()
            if not math.isfinite(loss_value):  # (before its gradients reach the weights; every later step would be NaN)
                step += 1
                raise diverged(f"the loss is {loss_value}")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            updating = True  # (from here to the average's update the state is between two steps)
            opt.step()
            sched.step()
            step += 1
            if cfg.ema:
                _ema_update(avg, net, min(cfg.ema, (1.0 + step) / (10.0 + step)))
            boundary_gen, boundary_loss, boundary_buffers, updating = gen.get_state(), loss_value, buffers_now(), False
            # (weights or BatchNorm statistics gone non-finite at this step: the statistics leave a training-mode loss
            # finite, and were found at the next save, which named its own step)
            # (one flag from the device, one wait for it a step: a GPU's update was waited on tensor by tensor)
            tensors = [(k, v) for k, v in (*net.named_parameters(), *boundary_buffers.items()) if v.is_floating_point()]
            if not bool(torch.stack([torch.isfinite(v).all() for _, v in tensors]).all()):
                bad = next(k for k, v in tensors if not bool(torch.isfinite(v).all()))
                raise diverged(f"the weights ({bad}) are not finite")
            if progress:
                progress(step, cfg.steps, loss_value)
            if step % cfg.val_every == 0 or step == cfg.steps:
                s, _, _ = _validate(avg, va, transform, cfg, worse)
                history.append({"step": step, "train_loss": loss_value, "val": s})
                log.info("step %d: train %s %.4f, val MAE %.4f, R2 %.3f", step, cfg.loss, loss_value, s["mae"], s["r2"])
            if step % cfg.save_every == 0 and step < cfg.steps:
                save(done=False)
        # the final validation and the safety margin (an interrupt here keeps the steps done too)
        val_scores, p, g = _validate(avg, va, transform, cfg, worse)
        dead = _dead_outputs(p, cfg.outputs)
        safety, under = calibrate_safety(p, g, worse=worse, quantile=cfg.safety_quantile)
        safe_scores = scores(p + worse * safety, g, worse=worse).as_dict()
        extra = {
            # (R² is NaN, undefined, on validation targets all of one value: null in the provenance, which holds only JSON
            # values; it failed the final save, after every step)
            "validation": _json_numbers({"transformed": val_scores, "with_safety": safe_scores}),
            "safety_rule": "mean underestimation" if cfg.safety_quantile is None else f"quantile {cfg.safety_quantile}",
            "underestimated_share_with_safety": under,
            "history": _json_numbers(history[-20:]),
            **({"head": cfg.head} if cfg.arch == "paper" else {}),  # (the fast network reads no head: none recorded)
            "arch": cfg.arch,
            **({"grow": cfg.grow} if cfg.grow != 1 else {}),
            **({"max_width": cfg.max_width} if cfg.max_width else {}),
            **({"separable": True} if cfg.separable else {}),
            **({"separable_tail": True} if cfg.separable_tail else {}),
            **({"tail_width": cfg.tail_width} if cfg.tail_width else {}),
            **({"head_width": cfg.head_width} if cfg.head_width else {}),
            **({"context_pool": cfg.context_pool} if cfg.context_pool else {}),
            **({"coarse": cfg.coarse, "coarse_width": cfg.coarse_width} if cfg.coarse else {}),
            **({"block_contrast": list(cfg.block_contrast)} if cfg.block_contrast else {}),
            **({"contrast_cell": cfg.contrast_cell} if cfg.contrast_cell else {}),
            **({"contrast_max": True} if cfg.contrast_max else {}),
            **({"stem_layers": cfg.stem_layers} if cfg.stem_layers != 1 else {}),
            **({"energy_norm": True} if cfg.energy_norm else {}),
            "augment": cfg.augment,
            **({"mirror": True} if cfg.mirror else {}),
            **({"context": cfg.context} if cfg.context else {}),
            "loss": cfg.loss,
            **({"quantile": cfg.quantile} if cfg.loss == "quantile" else {}),
            **({"focus": cfg.focus} if cfg.focus else {}),
            **({"ema": cfg.ema} if cfg.ema else {}),
            **({"teachers": [Path(t).name for t in cfg.teachers], "distill": cfg.distill} if cfg.teachers else {}),
            **({"aux_metrics": list(cfg.aux_metrics), "aux_weight": cfg.aux_weight} if cfg.aux_metrics else {}),
            "dead_outputs": dead,
        }
        save(done=True, safety=safety, extra=extra)
    except KeyboardInterrupt:
        if not updating and step > saved_step:
            with torch.no_grad():  # (the statistics of the step boundary, not those of a forward pass cut short)
                for buffer_name, buffer in net.named_buffers():
                    buffer.copy_(boundary_buffers[buffer_name])
            # (a validation the interrupt kept from the history, owed at this step: a resumed run makes it first)
            owed = (step % cfg.val_every == 0 or step == cfg.steps) and (not history or history[-1]["step"] != step)
            save(done=False, generator=boundary_gen, pending=boundary_loss if owed else None)
            log.info("interrupted: %s holds step %d", out, step)
        raise
    if dead:
        why = f" (a ReLU in the {cfg.head!r} head that stopped firing)" if cfg.arch == "paper" else ""
        log.warning("%s: output(s) %s predict the same value on every validation tile%s: such a model picks rates "
                    "blindly", out, ", ".join(dead), why)
    log.info("done: val R2 %.3f MAE %.4f; safety %.4f leaves %.1f%% underestimated", val_scores["r2"],
             val_scores["mae"], safety, 100 * under)
    return TrainResult(out, step, {"transformed": val_scores, "with_safety": safe_scores}, safety, under, dead)

