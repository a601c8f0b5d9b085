"""Turn trained checkpoints into ONNX models that carry their metadata (the ``rtp-export`` command is
:func:`rtp.cli.export_main`)."""

from ._export import (
    COMPUTED_FIELDS,
    DEFAULT_OPSET,
    PLANES_PER_INPUT,
    PROBE_NODES,
    RAW_RANGE,
    RETUNE_FIELDS,
    TRAINED_FIELDS,
    ExportError,
    add_finite_probe,
    adopt,
    export_checkpoint,
    join_input_planes,
    merge_slices,
    restamp,
    retune,
    split_input_planes,
    strip_finite_probe,
    write_metadata,
)
from ._published import PublishedModel, identify, published_models

__all__ = [
    "COMPUTED_FIELDS", "DEFAULT_OPSET", "PLANES_PER_INPUT", "PROBE_NODES", "RAW_RANGE", "RETUNE_FIELDS", "TRAINED_FIELDS",
    "ExportError",
    "PublishedModel", "add_finite_probe", "adopt", "export_checkpoint", "identify", "join_input_planes", "merge_slices",
    "published_models", "restamp", "retune", "split_input_planes", "strip_finite_probe", "write_metadata"
]
