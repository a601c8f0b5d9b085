"""The rtp error tree.

Every error the SDK raises derives from :class:`RtpError`, so an engine can catch one type.
Where a standard Python type fits, the error also derives from it, so generic handlers keep
working::

    RtpError
    ├── ModelNotFoundError        (also FileNotFoundError)  no file at the path, no shipped model of that name
    ├── ModelLoadError                                      the file exists but is not a loadable ONNX model
    ├── MetadataError             (also ValueError)         metadata missing, malformed or inconsistent with the graph
    ├── InputError                (also ValueError)         base of the bad-input errors below
    │   ├── InputShapeError                                 wrong rank, size or layout
    │   │   └── InputChannelError                           wrong number of channels
    │   ├── InputDtypeError       (also TypeError)          not a float32 numpy array
    │   └── NonFiniteInputError                             NaN or inf in the input
    ├── ParameterError            (also ValueError)         an argument out of its range (threshold, tile size, ...)
    ├── ProviderUnavailableError                            an execution provider that was asked for does not run
    └── InferenceError                                      onnxruntime failed while running the model

Messages say what was expected and what arrived. No bare onnxruntime exception leaves the SDK:
they are re-raised as one of these, chained with ``from``.
"""

from __future__ import annotations

__all__ = [
    "InferenceError",
    "InputChannelError",
    "InputDtypeError",
    "InputError",
    "InputShapeError",
    "MetadataError",
    "ModelLoadError",
    "ModelNotFoundError",
    "NonFiniteInputError",
    "ParameterError",
    "ProviderUnavailableError",
    "RtpError",
]


class RtpError(Exception):
    """Base class of every error raised by rtp."""


class ModelNotFoundError(RtpError, FileNotFoundError):
    """No model file at the given path and no shipped model of that name."""


class ModelLoadError(RtpError):
    """The file exists but onnxruntime cannot load it (corrupt, truncated, not ONNX)."""


class MetadataError(RtpError, ValueError):
    """Model metadata is missing, malformed, of an unsupported schema, or does not fit the graph.

    ``key`` names the offending metadata field when there is one.
    """

    def __init__(self, message: str, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


class InputError(RtpError, ValueError):
    """Base class of errors about the tensor passed to ``predict`` / ``shading_rates``."""


class InputShapeError(InputError):
    """The input has the wrong rank, spatial size or layout.

    ``actual`` and ``expected`` describe the shapes involved.
    """

    def __init__(self, message: str, actual: tuple[int, ...] | None = None, expected: str | None = None) -> None:
        super().__init__(message)
        self.actual = actual
        self.expected = expected


class InputChannelError(InputShapeError):
    """The input has a different number of channels than the model's metadata declares."""


class InputDtypeError(InputError, TypeError):
    """The input is not a numpy array of dtype float32."""


class NonFiniteInputError(InputError):
    """The input contains NaN or infinite values."""


class ParameterError(RtpError, ValueError):
    """An argument is of the wrong type or outside its range (a threshold, a tile size, a rate name).

    ``name`` names the argument when there is one.
    """

    def __init__(self, message: str, name: str | None = None) -> None:
        super().__init__(message)
        self.name = name


class ProviderUnavailableError(RtpError):
    """An execution provider that was asked for is not available or did not take the session."""


class InferenceError(RtpError):
    """onnxruntime failed while running the model, or produced an output of an unexpected shape."""
