"""Turn trained checkpoints into ONNX models that carry their metadata (the ``rtp-export`` command is
:func:`rtp.cli.export_main`)."""

from ._export import DEFAULT_OPSET, ExportError, add_finite_probe, adopt, export_checkpoint, restamp, write_metadata
from ._published import PublishedModel, identify, published_models

__all__ = ["DEFAULT_OPSET", "ExportError", "PublishedModel", "add_finite_probe", "adopt", "export_checkpoint", "identify",
           "published_models", "restamp", "write_metadata"]
