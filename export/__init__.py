"""Turn trained checkpoints into ONNX models that carry their metadata (the ``rtp-export`` command is
:func:`rtp.cli.export_main`)."""

from ._export import DEFAULT_OPSET, ExportError, adopt, export_checkpoint, restamp, write_metadata

__all__ = ["DEFAULT_OPSET", "ExportError", "adopt", "export_checkpoint", "restamp", "write_metadata"]
