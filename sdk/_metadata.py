"""Model metadata: the schema, validation, and the decode from network output to metric units.

A model carries one JSON object under the ONNX ``metadata_props`` key :data:`METADATA_KEY`. It is
parsed with ``json.loads`` and validated field by field; nothing in it is ever evaluated. Every
field is documented in ``docs/metadata.md``.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import os
import re
import reprlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ._channels import CHANNELS
from ._errors import MetadataError, ParameterError
from ._metrics import METRIC_NAME_PATTERN, METRICS
from ._rates import MAX_THRESHOLD, PREDICTED_RATES, check_rate_factors
from ._tiles import TILE_SIZES
from ._transforms import DEFAULT_EXTRAPOLATION_K, MAX_EXTRAPOLATION_K, OUTPUT_SETS, Transform, as_float64, extrapolate

__all__ = ["FEATURES_NAME", "METADATA_KEY", "SCHEMA_VERSION", "TAIL_KEY", "ModelMetadata"]

#: The ``metadata_props`` key that holds the JSON metadata.
METADATA_KEY = "rtp.metadata"
#: The newest metadata schema this SDK reads (it reads every older one too). Version 2 added
#: ``input_multiple``, version 3 ``finite_probe``, version 4 ``tail``, version 5 ``rate_factors``;
#: metadata is written with the lowest version that holds its fields, so a model without them stays
#: readable by an SDK that knows only version 1.
SCHEMA_VERSION = 5
#: The ``metadata_props`` key of a splitting model's tail graph (``ModelMetadata.tail``), base64.
TAIL_KEY = "rtp.tail"
#: The graph output of a splitting model's trunk features (``ModelMetadata.tail``).
FEATURES_NAME = "features"
_METRIC_RE = re.compile(METRIC_NAME_PATTERN)
_OUTPUT_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_.:/-]{0,127}")
_FIELDS = (
    "schema_version",
    "metric",
    "higher_is_better",
    "transform",
    "safety",
    "tile_size",
    "input_multiple",
    "finite_probe",
    "tail",
    "inputs",
    "outputs",
    "extrapolation_k",
    "default_threshold",
    "rate_factors",
    "weber_l",
    "description",
    "provenance",
    "digest",
)
#: The form of ``digest``: ``sha256:`` and 64 lower-case hex digits (``sdk.model_digest``).
DIGEST_RE = re.compile(r"sha256:[0-9a-f]{64}")


def _number(
    d: Mapping[str, Any], key: str, *, default: Any = ..., minimum: float | None = None, maximum: float | None = None
) -> float:
    if key not in d or d[key] is None:
        if default is ...:
            raise MetadataError(f"{key}: required, missing", key)
        return default
    v = d[key]  # (numpy's numbers too, as a threshold or margin computed with numpy is)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) or not _finite(v):
        raise MetadataError(f"{key}: expected a finite number, got {reprlib.repr(v)}", key)
    if (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        lo = "" if minimum is None else f">= {minimum:g}"
        hi = "" if maximum is None else f"<= {maximum:g}"
        raise MetadataError(f"{key}: expected a number {' and '.join(x for x in (lo, hi) if x)}, got {v:g}", key)
    return float(v)


def _integer(v: Any) -> Any:
    """A numpy integer as Python's (``np.int64(16)`` was "expected one of (1, ..., 16, 32)"); anything else as it is."""
    return int(v) if isinstance(v, np.integer) else v


def _finite(v: float | np.integer | np.floating) -> bool:
    try:
        return math.isfinite(v)
    except OverflowError:  # an int too large for a float
        return False


#: The deepest nesting of ``provenance`` (the shipped models' is 4). Deeper is a MetadataError: it
#: was left to ``json.dumps``'s RecursionError, which Python 3.12 and later raise only past about
#: 10,000 levels while the copy, freeze and thaw of the metadata fail past about 1,000 (a bare
#: RecursionError from ``from_dict`` on 3.13).
MAX_PROVENANCE_DEPTH = 100


def _depth_over(value: Any, limit: int) -> bool:
    """Whether ``value`` (mappings, lists and tuples of values) nests more than ``limit`` levels deep;
    walked without recursion, so any depth is answered."""
    stack = [(value, 0)]
    while stack:
        v, level = stack.pop()
        children = v.values() if isinstance(v, Mapping) else v if isinstance(v, (list, tuple)) else None
        if children is None:
            continue
        if level >= limit:
            return True
        stack.extend((c, level + 1) for c in children)
    return False


def _freeze(value: Any) -> Any:
    if isinstance(value, Mapping):
        return MappingProxyType({k: _freeze(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(_freeze(v) for v in value)
    return value


def _thaw(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return [_thaw(v) for v in value]
    return value


@dataclass(frozen=True)
class ModelMetadata:
    """Everything the runtime needs to turn a network's output into shading rates.

    Build with :meth:`from_dict`, :meth:`from_json` or :meth:`from_yaml`; each validates and raises
    :class:`~rtp.sdk.MetadataError` naming the offending key.
    """

    metric: str
    higher_is_better: bool
    transform: Transform
    tile_size: int
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    default_threshold: float
    safety: float = 0.0
    extrapolation_k: float = DEFAULT_EXTRAPOLATION_K
    weber_l: float | None = None
    description: str = ""
    provenance: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    #: The network takes any frame whose height and width are multiples of this and returns
    #: ``ceil(H/tile_size) x ceil(W/tile_size)`` tiles, a last partial tile seeing only the pixels it
    #: covers; ``predict`` pads a frame only up to this multiple. None (models before schema 2, the
    #: paper's network): the frame is padded up to whole tiles by repeating its last row and column.
    input_multiple: int | None = None
    #: The name of a second graph output, a float scalar that is NaN or infinite whenever the input
    #: holds a NaN or an infinity (``rtp-export`` adds it: the summed per-channel means of the first
    #: convolution's output before its activation, which reads every pixel). ``predict`` then checks that scalar instead
    #: of reading the whole frame once more. None: the SDK checks the frame itself.
    finite_probe: str | None = None
    #: A network that splits (``docs/runtime.md`` "Carrying a split network's features"): the digest
    #: (``"sha256:<hex>"``, :func:`sdk.model_digest`) of its tail, a second ONNX graph held base64 under
    #: the ``metadata_props`` key ``rtp.tail``, which maps the trunk's per-tile features (the model's
    #: output ``features``) and a frame to the outputs. None: the model does not split.
    tail: str | None = None
    #: Each reduced rate's threshold factor, :data:`PREDICTED_RATES` order (``select_rates(factors=)``):
    #: rate r passes below ``threshold x rate_factors[r]`` (PSNR: above ``threshold - 20 log10`` of it).
    #: All 1 (the default): one threshold for every rate.
    rate_factors: tuple[float, ...] = (1.0,) * len(PREDICTED_RATES)
    schema_version: int = 1
    #: ``"sha256:<hex>"`` of the graph and weights (``rtp-export`` writes it; ``sdk.load`` checks it), or None.
    digest: str | None = None

    def __post_init__(self) -> None:
        try:  # a tuple of six checked factors however it was built (dataclasses.replace included)
            object.__setattr__(self, "rate_factors", check_rate_factors(self.rate_factors, "rate_factors"))
        except ParameterError as err:
            raise MetadataError(str(err), "rate_factors") from err
        # the lowest schema that holds the fields (see SCHEMA_VERSION)
        version = (5 if any(f != 1.0 for f in self.rate_factors) else 4 if self.tail is not None
                   else 3 if self.finite_probe is not None else 1 if self.input_multiple is None else 2)
        object.__setattr__(self, "schema_version", version)

    # -- parsing ------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ModelMetadata:
        if not isinstance(d, Mapping):
            raise MetadataError(f"metadata: expected a mapping, got {type(d).__name__}")
        odd = [k for k in d if not isinstance(k, str)]
        if odd:
            raise MetadataError(f"metadata: field names must be strings, got {odd[0]!r}")
        unknown = sorted(set(d) - set(_FIELDS))
        if unknown:
            import difflib

            # (a sidecar's 'default_treshold'; a field's start, 'tile', is read as that field before a close spelling)
            close = [f for f in _FIELDS if f.startswith(unknown[0])][:1] or difflib.get_close_matches(unknown[0], _FIELDS, n=1)
            raise MetadataError(
                f"{unknown[0]}: unknown metadata field{f' (did you mean {close[0]}?)' if close else ''}; known fields "
                f"are {', '.join(_FIELDS)}", unknown[0]
            )
        version = _integer(d.get("schema_version", SCHEMA_VERSION))
        if isinstance(version, bool) or not isinstance(version, int) or version < 1:
            raise MetadataError(f"schema_version: expected a positive integer, got {version!r}", "schema_version")
        if version > SCHEMA_VERSION:
            raise MetadataError(
                f"schema_version: the model uses metadata schema {version}, this rtp reads up to "
                f"{SCHEMA_VERSION}; upgrade rtp",
                "schema_version",
            )

        metric = d.get("metric")
        if not isinstance(metric, str) or not _METRIC_RE.fullmatch(metric):
            raise MetadataError(f"metric: expected a lower-case name such as 'jnyang', got {metric!r}", "metric")
        hib = d.get("higher_is_better")
        if hib is None:
            if metric not in METRICS:
                raise MetadataError(
                    f"higher_is_better: required for the metric {metric!r}, which rtp does not know", "higher_is_better"
                )
            hib = METRICS[metric].higher_is_better
        if not isinstance(hib, (bool, np.bool_)):
            raise MetadataError(f"higher_is_better: expected true or false, got {hib!r}", "higher_is_better")
        hib = bool(hib)
        if metric in METRICS and hib != METRICS[metric].higher_is_better:
            raise MetadataError(
                f"higher_is_better: {metric} is {'higher' if METRICS[metric].higher_is_better else 'lower'}-is-better, "
                f"metadata says {hib}",
                "higher_is_better",
            )

        if "transform" not in d:
            raise MetadataError("transform: required, missing", "transform")
        transform = Transform.from_dict(d["transform"])

        tile = _integer(d.get("tile_size"))
        if isinstance(tile, bool) or not isinstance(tile, int) or tile not in TILE_SIZES:
            raise MetadataError(f"tile_size: expected one of {TILE_SIZES}, got {tile!r}", "tile_size")

        multiple = _integer(d.get("input_multiple"))
        if multiple is not None and (
            isinstance(multiple, bool) or not isinstance(multiple, int) or multiple not in TILE_SIZES or multiple > tile
        ):
            raise MetadataError(
                f"input_multiple: expected one of {[s for s in TILE_SIZES if s <= tile]} (a power of two up to "
                f"tile_size {tile}) or null, got {multiple!r}",
                "input_multiple",
            )

        probe = d.get("finite_probe")
        if probe is not None and (not isinstance(probe, str) or not _OUTPUT_NAME_RE.fullmatch(probe)):
            raise MetadataError(
                f"finite_probe: expected the name of a graph output (letters, digits, '_', '.', ':', '/', '-') or "
                f"null, got {reprlib.repr(probe)}",
                "finite_probe",
            )

        inputs = d.get("inputs")
        if not isinstance(inputs, (list, tuple)) or not inputs or not all(isinstance(c, str) for c in inputs):
            raise MetadataError(f"inputs: expected a non-empty list of channel names, got {inputs!r}", "inputs")
        bad = [c for c in inputs if c not in CHANNELS]
        if bad:
            raise MetadataError(f"inputs: unknown channel {bad[0]!r}; known channels: {', '.join(CHANNELS)}", "inputs")
        if len(set(inputs)) != len(inputs):
            raise MetadataError(f"inputs: channel names must be distinct, got {list(inputs)}", "inputs")

        outputs = d.get("outputs")
        if not isinstance(outputs, (list, tuple)) or tuple(outputs) not in OUTPUT_SETS:
            raise MetadataError(
                f"outputs: expected the rates of the network's channels, one of {[list(s) for s in OUTPUT_SETS]}; "
                f"got {outputs!r}",
                "outputs",
            )

        weber = d.get("weber_l")
        if weber is not None:
            weber = _number(d, "weber_l", minimum=0.0)
        elif metric.startswith("jn"):
            raise MetadataError(
                f"weber_l: required for the Weber-corrected metric {metric!r} (the environment luminance l)", "weber_l"
            )

        # (null, as YAML reads an empty `description:`, is none, as rtp-export --retune takes it: it was refused here)
        description = "" if d.get("description") is None else d["description"]
        if not isinstance(description, str):
            raise MetadataError(f"description: expected a string, got {description!r}", "description")
        provenance = d.get("provenance", {})
        if not isinstance(provenance, Mapping):
            raise MetadataError(f"provenance: expected a mapping, got {type(provenance).__name__}", "provenance")
        if _depth_over(provenance, MAX_PROVENANCE_DEPTH):
            raise MetadataError(f"provenance: nested more than {MAX_PROVENANCE_DEPTH} levels deep", "provenance")
        try:
            json.dumps(provenance, allow_nan=False)
        except (TypeError, ValueError, RecursionError) as err:  # RecursionError: nested too deep
            raise MetadataError(f"provenance: must hold only JSON values: {err}", "provenance") from err

        # >= 1: a coarser rate never has less error; <= MAX_EXTRAPOLATION_K: the paper's is 2.13
        k = _number(d, "extrapolation_k", default=DEFAULT_EXTRAPOLATION_K, minimum=1.0, maximum=MAX_EXTRAPOLATION_K)
        # an error metric's threshold is an error: never negative; PSNR's is any finite dB value
        threshold = _number(d, "default_threshold", minimum=-MAX_THRESHOLD if hib else 0.0, maximum=MAX_THRESHOLD)
        factors = d.get("rate_factors")
        if factors is not None and not isinstance(factors, Mapping):
            raise MetadataError(f"rate_factors: expected a mapping of rate names ({', '.join(PREDICTED_RATES)}) to "
                                f"threshold factors, or null, got {reprlib.repr(factors)}", "rate_factors")
        try:
            rate_factors = check_rate_factors(factors, "rate_factors")
        except ParameterError as err:
            raise MetadataError(str(err), "rate_factors") from err
        tail = d.get("tail")
        if tail is not None and (not isinstance(tail, str) or not DIGEST_RE.fullmatch(tail)):
            raise MetadataError(f"tail: expected the digest of the tail graph ('sha256:' and 64 hex digits) or null, got "
                                f"{reprlib.repr(tail)}", "tail")

        digest = d.get("digest")
        if digest is not None and (not isinstance(digest, str) or not DIGEST_RE.fullmatch(digest)):
            raise MetadataError(f"digest: expected 'sha256:' and 64 hex digits, got {digest!r}", "digest")
        return cls(
            metric=metric,
            higher_is_better=hib,
            transform=transform,
            tile_size=int(tile),
            inputs=tuple(inputs),
            outputs=tuple(outputs),
            default_threshold=threshold,
            # in transformed space, where the network's outputs lie in (0, 1)
            safety=_number(d, "safety", default=0.0, minimum=0.0, maximum=1.0),
            extrapolation_k=k,
            weber_l=weber,
            description=description,
            provenance=_freeze(copy.deepcopy(dict(provenance))),
            input_multiple=None if multiple is None else int(multiple),
            finite_probe=probe,
            tail=tail,
            rate_factors=rate_factors,
            digest=digest,
        )

    @classmethod
    def from_json(cls, text: str) -> ModelMetadata:
        if not isinstance(text, (str, bytes, bytearray)):
            raise MetadataError(f"{METADATA_KEY}: expected JSON text, got {type(text).__name__}", METADATA_KEY)
        try:
            d = json.loads(text)
        except (ValueError, RecursionError) as err:  # JSONDecodeError, bad UTF-8, huge ints, deep nesting
            raise MetadataError(f"{METADATA_KEY}: not valid JSON ({type(err).__name__}: {err})", METADATA_KEY) from err
        return cls.from_dict(d)

    @classmethod
    def from_yaml(cls, path: str | os.PathLike[str]) -> ModelMetadata:
        """Read a YAML sidecar (the same fields as the JSON)."""
        import yaml

        if not isinstance(path, (str, os.PathLike)):
            raise MetadataError(f"metadata sidecar: expected a YAML file path, got {type(path).__name__}")
        try:
            p = Path(path)
            text = p.read_text(encoding="utf-8")
        except FileNotFoundError as err:
            from ._errors import ModelNotFoundError

            raise ModelNotFoundError(f"metadata sidecar not found: {path}") from err
        except (OSError, ValueError, TypeError) as err:  # unreadable, not UTF-8, a NUL byte in the path
            raise MetadataError(f"{reprlib.repr(str(path))}: cannot be read as a UTF-8 YAML sidecar ({err})") from err
        from .files import read_sidecar

        try:
            d = read_sidecar(text)
        except (yaml.YAMLError, RecursionError, ValueError) as err:
            from .files import yaml_problem

            raise MetadataError(f"{p}: not valid YAML ({yaml_problem(err)})") from err
        if d is not None and not isinstance(d, dict):
            raise MetadataError(f"{p}: expected a YAML sidecar, a mapping of metadata fields (docs/metadata.md), got "
                                f"a {type(d).__name__}")
        try:
            return cls.from_dict(d if d is not None else {})
        except MetadataError as err:  # the field's error, and the file it is in
            raise MetadataError(f"{p}: {err}", err.key) from err

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": self.schema_version,
            "metric": self.metric,
            "higher_is_better": self.higher_is_better,
            "transform": self.transform.to_dict(),
            "safety": self.safety,
            "tile_size": self.tile_size,
            **({"input_multiple": self.input_multiple} if self.input_multiple is not None else {}),
            **({"finite_probe": self.finite_probe} if self.finite_probe is not None else {}),
            **({"tail": self.tail} if self.tail is not None else {}),
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "extrapolation_k": self.extrapolation_k,
            "default_threshold": self.default_threshold,
            **({"rate_factors": dict(zip(PREDICTED_RATES, self.rate_factors))}
               if any(f != 1.0 for f in self.rate_factors) else {}),
            "weber_l": self.weber_l,
            "description": self.description,
            "provenance": _thaw(self.provenance),
            **({"digest": self.digest} if self.digest is not None else {}),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), allow_nan=False)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled (and deep-copied) as its dict, built again through :meth:`from_dict`: its provenance is
        held read-only (``MappingProxyType``), which pickle cannot copy as it is."""
        return type(self).from_dict, (self.to_dict(),)

    # -- decoding -----------------------------------------------------------------------------
    @property
    def pad_multiple(self) -> int:
        """What a frame's height and width are padded up to before the network sees them:
        ``input_multiple``, or ``tile_size`` for a model without one."""
        return self.tile_size if self.input_multiple is None else self.input_multiple

    @property
    def worse_direction(self) -> float:
        """+1 when a larger transformed value means a worse image, -1 otherwise.

        The safety margin is applied in this direction, so it is always conservative.
        """
        return 1.0 if self.transform.increasing != self.higher_is_better else -1.0

    @functools.cached_property  # (computed once: shading_rates asks on every call; the fields never change)
    def rate_saturations(self) -> tuple[float, ...]:
        """The worst value the model can express for each reduced rate (:data:`PREDICTED_RATES` order): the
        network's worst output (1, or 0 where a smaller transformed value is worse) plus the margin, decoded and
        extrapolated as :meth:`decode` does. A rate the network outputs, and 2x2 and 4x4 extrapolated from four,
        saturate at the decoded worst output; 2x4, 4x2 and 4x4 extrapolated from ``[1x2, 2x1]`` or ``[2x2]`` reach
        ``extrapolation_k`` times it (PSNR: ``20 log10 k`` dB lower)."""
        p = 1.0 if self.worse_direction > 0 else 0.0
        worst = self.transform.inverse(np.full((len(self.outputs), 1, 1), p + self.worse_direction * self.safety))
        full = extrapolate(worst, self.outputs, self.extrapolation_k, higher_is_better=self.higher_is_better)
        return tuple(float(v) for v in full[:, 0, 0])

    @property
    def saturation(self) -> float:
        """The worst metric value the model can express at any rate (the worst of :attr:`rate_saturations`):
        a threshold beyond it passes every tile at every rate."""
        sat = self.rate_saturations
        return min(sat) if self.higher_is_better else max(sat)

    @functools.cached_property  # (computed once, as rate_saturations: the runtimes ask on every frame)
    def rate_bests(self) -> tuple[float, ...]:
        """The best value the model can express for each reduced rate (:data:`PREDICTED_RATES` order), the
        counterpart of :attr:`rate_saturations`: the network's best output (0, or 1 where a larger transformed value
        is better) plus the margin, which moves every output towards the worse side, decoded and extrapolated as
        :meth:`decode` does."""
        p = 0.0 if self.worse_direction > 0 else 1.0
        best = self.transform.inverse(np.full((len(self.outputs), 1, 1), p + self.worse_direction * self.safety))
        full = extrapolate(best, self.outputs, self.extrapolation_k, higher_is_better=self.higher_is_better)
        return tuple(float(v) for v in full[:, 0, 0])

    def _passes_everything(self, threshold: float) -> bool:
        """Whether ``threshold``, with each rate's ``rate_factors`` share of it (as ``select_rates`` applies them),
        lies beyond the worst value the model can express at every rate (:attr:`rate_saturations`): every tile then
        passes at every rate, whatever the frame."""
        hib, t = self.higher_is_better, float(threshold)
        return all((t - 20.0 * math.log10(f) < sat) if hib else (t * f > sat)
                   for sat, f in zip(self.rate_saturations, self.rate_factors))

    def _passes_nothing(self, threshold: float) -> bool:
        """Whether ``threshold``, with each rate's ``rate_factors`` share of it, lies beyond the best value the model
        can express at every rate (:attr:`rate_bests`): no tile then passes at any rate and every tile gets 1x1,
        whatever the frame. (Strictly beyond: at the best value itself a float32 prediction rounded below it could
        still pass.)"""
        hib, t = self.higher_is_better, float(threshold)
        return all((t - 20.0 * math.log10(f) > best) if hib else (t * f < best)
                   for best, f in zip(self.rate_bests, self.rate_factors))

    def threshold_warning(self, threshold: float, *, budget: bool = False) -> str | None:
        """What a runtime warns of ``threshold`` where the model's output decides it alone, whatever the frame; None
        where it does not (some tile may pass it and some fail). Beyond the worst value the model can express at
        every rate (each rate's ``rate_factors`` share of it past :attr:`rate_saturations`) every tile passes it at
        every rate; beyond the best value (past :attr:`rate_bests`) no tile passes it at any rate, every tile 1x1
        (VRS off: often a threshold in another metric's units). The text names the threshold to go past.
        ``ShadingRatePredictor.shading_rates``, ``PredictionReuse.shading_rates`` and the GPU ``RateSelector`` log
        it once per threshold (the first 16 thresholds), after the model's name.

        ``budget``: the threshold is a floor under a budget (``saving=``): only the first end is said, since below
        the second the budget's rates are taken on every frame, as without a threshold."""
        hib, t = self.higher_is_better, float(threshold)
        if not budget and self._passes_nothing(t):
            # below each rate's limit that rate passes no tile: the first rate to pass some sets the limit
            limits = [best + 20.0 * math.log10(f) if hib else best / f
                      for best, f in zip(self.rate_bests, self.rate_factors)]
            best = max(self.rate_bests) if hib else min(self.rate_bests)
            return (f"threshold {t:g} is beyond the best value the model can express ({best:g}): no tile passes it "
                    f"at any rate, every tile gets 1x1 on every frame; use one {'below' if hib else 'above'} "
                    f"{max(limits) if hib else min(limits):g} (a threshold in another metric's units?)")
        if not self._passes_everything(t):
            return None
        # past each rate's limit that rate passes every tile: the last rate to do so sets the limit
        limits = [sat + 20.0 * math.log10(f) if hib else sat / f for sat, f in zip(self.rate_saturations,
                                                                                    self.rate_factors)]
        return (f"threshold {t:g} is beyond the worst value the model can express ({self.saturation:g}): every tile "
                f"passes it at every rate; use one {'above' if hib else 'below'} "
                f"{min(limits) if hib else max(limits):g}")

    def decode(self, raw: np.ndarray) -> np.ndarray:
        """Network output (channels = :attr:`outputs`, axis -3) to metric units for all six rates.

        Adds the safety margin in the conservative direction, applies the inverse transform and
        extrapolates the missing rates. Returns float32 with six channels on axis -3.
        """
        p = as_float64(raw, "raw") + self.worse_direction * self.safety
        values = self.transform.inverse(p)
        full = extrapolate(values, self.outputs, self.extrapolation_k, higher_is_better=self.higher_is_better)
        return full.astype(np.float32)
