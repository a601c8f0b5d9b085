"""Model integrity: a digest of an ONNX model's graph and weights that the metadata carries.

The digest is SHA-256 over the serialized ``ModelProto`` without its ``metadata_props`` entries
(field 14), so writing metadata never changes it while a change anywhere in the graph, the weights,
the opsets or the producer does. It is recomputed from the file's bytes with the standard library
alone (a small protobuf wire-format walk): the runtime needs no ``onnx`` package to check it.
"""

from __future__ import annotations

import hashlib

__all__ = ["DIGEST_ALGORITHM", "model_digest"]

#: The prefix of the digest string: ``"sha256:<64 hex digits>"``.
DIGEST_ALGORITHM = "sha256"
_METADATA_PROPS = 14  # ModelProto.metadata_props


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if i >= len(data) or shift > 63:
            raise ValueError("truncated or malformed varint")
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, i
        shift += 7


def _without_field(data: bytes, field: int) -> bytes:
    """The top-level protobuf fields of ``data`` in order, minus every entry of ``field``."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        start = i
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise ValueError("field number 0")
        if wire == 0:
            _, i = _varint(data, i)
        elif wire == 1:
            i += 8
        elif wire == 2:
            length, i = _varint(data, i)
            i += length
        elif wire == 5:
            i += 4
        else:
            raise ValueError(f"unsupported wire type {wire}")
        if i > n:
            raise ValueError("truncated field")
        if number != field:
            out += data[start:i]
    return bytes(out)


def model_digest(data: bytes) -> str:
    """``"sha256:<hex>"`` of a serialized ONNX model's graph and weights (everything but its
    metadata_props). Raises :class:`~rtp.sdk.ParameterError` (a ``ValueError``) for anything but the
    bytes of a protobuf message."""
    from ._errors import ParameterError

    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ParameterError(f"model_digest: expected the bytes of an ONNX model, got {type(data).__name__}")
    try:
        return _digest(bytes(data))
    except ValueError as err:
        raise ParameterError(f"model_digest: not the bytes of an ONNX model ({err})") from err


def _digest(data: bytes) -> str:
    return f"{DIGEST_ALGORITHM}:{hashlib.sha256(_without_field(data, _METADATA_PROPS)).hexdigest()}"
