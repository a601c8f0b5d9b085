"""The rtp error tree.

Every error the SDK raises derives from :class:`RtpError`, so an engine can catch one type.
Where a standard Python type fits, the error also derives from it, so generic handlers keep
working::

    RtpError
    ├── ModelNotFoundError        (also FileNotFoundError)  no file at the path, no shipped model of that name
    ├── ModelLoadError                                      the file exists but is not a loadable ONNX model
    │   └── ModelIntegrityError                             graph or weights differ from the exported digest
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

Every class carries the exit code the command-line tools (``rtp``, ``rtp-export``) return for it:
:data:`EXIT_USAGE` (2) for errors about what the caller gave (arguments, files, metadata, arrays,
a missing install: fix it and run again), :data:`EXIT_FAILED` (1) when the job itself ran and
failed. :func:`exit_code` reads it; ``docs/errors.md`` lists every class with its code.
"""

from __future__ import annotations

__all__ = [
    "EXIT_FAILED",
    "EXIT_USAGE",
    "InferenceError",
    "InputChannelError",
    "InputDtypeError",
    "InputError",
    "InputShapeError",
    "MetadataError",
    "ModelIntegrityError",
    "ModelLoadError",
    "ModelNotFoundError",
    "NonFiniteInputError",
    "ParameterError",
    "ProviderUnavailableError",
    "RtpError",
    "exit_code",
]

#: Exit code of a job that ran and failed.
EXIT_FAILED = 1
#: Exit code of bad usage or bad inputs (arguments, files, metadata, arrays, a missing install).
EXIT_USAGE = 2
#: Exit code of a command interrupted with Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130


class RtpError(Exception):
    """Base class of every error raised by rtp. ``exit_code``: what the command-line tools return."""

    exit_code: int = EXIT_FAILED


class ModelNotFoundError(RtpError, FileNotFoundError):
    """No model file at the given path and no shipped model of that name."""

    exit_code = EXIT_USAGE


class ModelLoadError(RtpError):
    """The file exists but onnxruntime cannot load it (corrupt, truncated, not ONNX)."""

    exit_code = EXIT_USAGE


class ModelIntegrityError(ModelLoadError):
    """The model's graph or weights differ from what was exported: the digest its metadata records
    does not match the file (corrupted, or modified after export; or its weights re-saved outside the
    file as ONNX external data, which the message names with how to re-save them inside)."""


class MetadataError(RtpError, ValueError):
    """Model metadata is missing, malformed, of an unsupported schema, or does not fit the graph.

    ``key`` names the offending metadata field when there is one.
    """

    exit_code = EXIT_USAGE

    def __init__(self, message: str, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


class InputError(RtpError, ValueError):
    """Base class of errors about the tensor passed to ``predict`` / ``shading_rates``."""

    exit_code = EXIT_USAGE


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

    exit_code = EXIT_USAGE

    def __init__(self, message: str, name: str | None = None) -> None:
        super().__init__(message)
        self.name = name


class ProviderUnavailableError(RtpError):
    """An execution provider that was asked for is not available or did not take the session."""

    exit_code = EXIT_USAGE


class InferenceError(RtpError):
    """onnxruntime failed while running the model, or produced an output of an unexpected shape."""


def exit_code(error: BaseException) -> int:
    """The exit code of a command that stopped on ``error``: the class's own for rtp errors,
    :data:`EXIT_INTERRUPTED` for Ctrl-C, :data:`EXIT_FAILED` for anything else."""
    if isinstance(error, RtpError):
        return int(error.exit_code)
    if isinstance(error, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    return EXIT_FAILED
