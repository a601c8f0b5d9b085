"""rtp runtime SDK: load a trained error-prediction model and pick variable-rate-shading rates.

    from rtp import sdk
    predictor = sdk.load("jnyang.onnx")
    rates = predictor.shading_rates(inputs)        # (H/16, W/16) uint8 D3D12/Vulkan codes

Imports only numpy, onnxruntime and pyyaml. See docs/quickstart.md and docs/runtime.md.
"""

from __future__ import annotations

import logging
import typing as _typing

from . import adapters, files
from ._channels import (
    BLOCK_CELL,
    BLOCK_EPS,
    BLOCK_RATES,
    BLOCK_TILE,
    CHANNELS,
    DEFAULT_INPUTS,
    Channel,
    block_variances,
    depth_edges,
    pixel_differences,
    tile_variances,
)
from ._color import LUMA_WEIGHTS, linear_to_srgb, luma, srgb_to_linear
from ._digest import model_digest
from ._errors import (
    EXIT_FAILED,
    EXIT_USAGE,
    InferenceError,
    InputChannelError,
    InputDtypeError,
    InputError,
    InputShapeError,
    MetadataError,
    ModelIntegrityError,
    ModelLoadError,
    ModelNotFoundError,
    NonFiniteInputError,
    ParameterError,
    ProviderUnavailableError,
    RtpError,
    exit_code,
)
from ._metadata import FEATURES_NAME, METADATA_KEY, SCHEMA_VERSION, TAIL_KEY, ModelMetadata
from ._metrics import METRIC_NAME_PATTERN, METRICS, TARGET_METRICS, MetricInfo, mse_from_psnr, psnr_from_mse
from ._overlay import OVERLAY_COLOURS, OVERLAY_PALETTES, draw_rate_overlay
from ._planes import DEPTH_KINDS, GBUFFERS, NORMAL_SPACES, check_gbuffers, gbuffers_needed, input_planes
from ._predictor import ShadingRatePredictor, load, shipped_models
from ._rates import (
    ALL_RATES,
    COMBINERS,
    MAX_RATE_FACTOR,
    MAX_SAVING,
    MAX_THRESHOLD,
    PREDICTED_RATES,
    RATE_CODES,
    RATE_NAMES,
    RateLike,
    SavingSelection,
    check_threshold,
    combine_rates,
    rate_size,
    resolve_allowed,
    select_rates,
    select_rates_for_saving,
    work_saved,
)
from ._reproject import (
    CAMERA_KINDS,
    DEFAULT_REPROJECTION_TOLERANCE,
    MAX_REPROJECTION_TOLERANCE,
    check_projection,
    check_reprojection,
    reproject,
    reproject_positions,
)
from ._reuse import (
    MAX_CARRY_SCALE,
    MAX_RESCALE,
    REUSE_CARRIES,
    REUSE_REDUCTIONS,
    REUSE_UNSEEN,
    PredictionReuse,
    fetch_from_motion,
)
from ._tiles import (
    DEFAULT_TILE_SIZE,
    TILE_SIZES,
    hardware_tiles,
    padded_size,
    pool_tiles,
    split_tiles,
    tile_extents,
    tile_grid,
)
from ._transforms import (
    DEFAULT_EXTRAPOLATION_K,
    DEFAULT_OUTPUTS,
    LOGIT_EPS,
    OUTPUT_SETS,
    Transform,
    complete_rates,
    extrapolate,
)

logging.getLogger("rtp").addHandler(logging.NullHandler())


def _module_attribute(name: str) -> str:
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("rtp")
        except PackageNotFoundError:
            return "0+unknown"
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ``__version__`` is read on access (the installed distribution's). A type checker sees it declared, not a
# module ``__getattr__``: that would make every other name, a misspelt one included, exist (as a str).
if _typing.TYPE_CHECKING:
    __version__: str
else:
    __getattr__ = _module_attribute


__all__ = [
    "ALL_RATES",
    "BLOCK_CELL",
    "BLOCK_EPS",
    "BLOCK_RATES",
    "BLOCK_TILE",
    "CAMERA_KINDS",
    "CHANNELS",
    "COMBINERS",
    "DEFAULT_EXTRAPOLATION_K",
    "DEFAULT_INPUTS",
    "DEFAULT_OUTPUTS",
    "DEFAULT_REPROJECTION_TOLERANCE",
    "DEFAULT_TILE_SIZE",
    "DEPTH_KINDS",
    "EXIT_FAILED",
    "EXIT_USAGE",
    "FEATURES_NAME",
    "GBUFFERS",
    "LOGIT_EPS",
    "LUMA_WEIGHTS",
    "MAX_CARRY_SCALE",
    "MAX_RATE_FACTOR",
    "MAX_REPROJECTION_TOLERANCE",
    "MAX_RESCALE",
    "MAX_SAVING",
    "MAX_THRESHOLD",
    "METADATA_KEY",
    "METRICS",
    "METRIC_NAME_PATTERN",
    "NORMAL_SPACES",
    "OUTPUT_SETS",
    "OVERLAY_COLOURS",
    "OVERLAY_PALETTES",
    "PREDICTED_RATES",
    "RATE_CODES",
    "RATE_NAMES",
    "REUSE_CARRIES",
    "REUSE_REDUCTIONS",
    "REUSE_UNSEEN",
    "SCHEMA_VERSION",
    "TAIL_KEY",
    "TARGET_METRICS",
    "TILE_SIZES",
    "Channel",
    "InferenceError",
    "InputChannelError",
    "InputDtypeError",
    "InputError",
    "InputShapeError",
    "MetadataError",
    "ModelIntegrityError",
    "ModelLoadError",
    "ModelMetadata",
    "MetricInfo",
    "ModelNotFoundError",
    "NonFiniteInputError",
    "ParameterError",
    "PredictionReuse",
    "ProviderUnavailableError",
    "RateLike",
    "SavingSelection",
    "RtpError",
    "ShadingRatePredictor",
    "Transform",
    "adapters",
    "block_variances",
    "check_gbuffers",
    "check_projection",
    "check_reprojection",
    "check_threshold",
    "combine_rates",
    "complete_rates",
    "depth_edges",
    "draw_rate_overlay",
    "exit_code",
    "extrapolate",
    "fetch_from_motion",
    "files",
    "gbuffers_needed",
    "hardware_tiles",
    "input_planes",
    "linear_to_srgb",
    "load",
    "luma",
    "model_digest",
    "mse_from_psnr",
    "padded_size",
    "pixel_differences",
    "pool_tiles",
    "psnr_from_mse",
    "rate_size",
    "reproject",
    "reproject_positions",
    "resolve_allowed",
    "select_rates",
    "select_rates_for_saving",
    "shipped_models",
    "split_tiles",
    "srgb_to_linear",
    "tile_extents",
    "tile_grid",
    "tile_variances",
    "work_saved",
]

# Public objects report their stable path, not the private module they live in.
for _name in __all__:
    _obj = globals()[_name]
    if isinstance(_obj, type) or (callable(_obj) and hasattr(_obj, "__module__")):
        try:
            _obj.__module__ = __name__
        except (AttributeError, TypeError):
            pass
del _name, _obj
