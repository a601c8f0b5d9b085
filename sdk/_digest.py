"""Model integrity: a digest of an ONNX model's graph and weights that the metadata carries.

The digest is SHA-256 over the serialized ``ModelProto`` without its ``metadata_props`` entries
(field 14), so writing metadata never changes it while a change anywhere in the graph, the weights,
the opsets or the producer does. It is recomputed from the file's bytes with the standard library
alone (a small protobuf wire-format walk): the runtime needs no ``onnx`` package to check it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

__all__ = ["DIGEST_ALGORITHM", "external_tensors", "model_digest"]

#: The prefix of the digest string: ``"sha256:<64 hex digits>"``.
DIGEST_ALGORITHM = "sha256"
_METADATA_PROPS = 14  # ModelProto.metadata_props


def _varint(data: bytes | memoryview, i: int) -> tuple[int, int]:
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


def _walk(data: bytes | memoryview) -> Iterator[tuple[int, int, int, int, int]]:
    """The top-level protobuf fields of ``data`` in order, each as ``(number, wire type, start, payload start,
    end)`` (a varint's value is read again from its payload start; a length-delimited field's bytes are
    ``data[payload start:end]``); a ValueError where it is no protobuf message."""
    i, n = 0, len(data)
    while i < n:
        start = i
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise ValueError("field number 0")
        payload = i
        if wire == 0:
            _, i = _varint(data, i)
        elif wire == 1:
            i += 8
        elif wire == 2:
            length, payload = _varint(data, i)
            i = payload + length
        elif wire == 5:
            i += 4
        else:
            raise ValueError(f"unsupported wire type {wire}")
        if i > n:
            raise ValueError("truncated field")
        yield number, wire, start, payload, i


def _without_field(data: bytes, field: int) -> bytes:
    """The top-level protobuf fields of ``data`` in order, minus every entry of ``field``."""
    out = bytearray()
    for number, _, start, _, end in _walk(data):
        if number != field:
            out += data[start:end]
    return bytes(out)


#: The messages of a serialized ModelProto that hold tensors, each with its fields that are (or lead to) them:
#: field number -> the message it holds (onnx.proto).
_TENSOR_PATHS: dict[str, dict[int, str]] = {
    "model": {7: "graph", 25: "function"},  # ModelProto.graph, .functions
    "graph": {1: "node", 5: "tensor", 15: "sparse"},  # GraphProto.node, .initializer, .sparse_initializer
    "function": {7: "node"},  # FunctionProto.node
    "node": {5: "attribute"},  # NodeProto.attribute
    "attribute": {5: "tensor", 6: "graph", 10: "tensor", 11: "graph", 22: "sparse", 23: "sparse"},  # t, g, ...
    "sparse": {1: "tensor", 2: "tensor"},  # SparseTensorProto.values, .indices
}
_TENSOR_NAME, _EXTERNAL_DATA, _DATA_LOCATION = 8, 13, 14  # TensorProto.name, .external_data, .data_location
_EXTERNAL = 1  # TensorProto.DataLocation.EXTERNAL


def _fields(data: memoryview) -> tuple[list[tuple[int, int]], list[tuple[int, memoryview]]]:
    """The top-level protobuf fields of ``data``: its varint fields as (number, value) and its length-delimited
    ones as (number, bytes); a ValueError where it is no protobuf message."""
    varints: list[tuple[int, int]] = []
    nested: list[tuple[int, memoryview]] = []
    for number, wire, _, payload, end in _walk(data):
        if wire == 0:
            varints.append((number, _varint(data, payload)[0]))
        elif wire == 2:
            nested.append((number, data[payload:end]))
    return varints, nested


def _text(data: memoryview) -> str:
    return bytes(data).decode("utf-8", "replace")


def external_tensors(data: bytes) -> tuple[list[str], list[str]]:
    """The tensors of a serialized ONNX model whose data is stored outside it (``onnx.save_model(...,
    save_as_external_data=True)``: ``data_location`` EXTERNAL) and the files their ``external_data`` names
    (its ``location`` entries), each list in the order met; empty lists for a model that holds every tensor,
    or for bytes that are no ONNX model. Standard library only, as :func:`model_digest`."""
    names: list[str] = []
    locations: list[str] = []
    todo: list[tuple[memoryview, str]] = [(memoryview(bytes(data)), "model")]
    try:
        while todo:  # (a stack, not recursion: nesting is bounded by the file's size alone)
            message, kind = todo.pop()
            varints, nested = _fields(message)
            if kind == "tensor":
                entries = [v for number, v in nested if number == _EXTERNAL_DATA]
                if entries or (_DATA_LOCATION, _EXTERNAL) in varints:
                    name = [_text(v) for number, v in nested if number == _TENSOR_NAME]
                    names.append(name[-1] if name else "?")
                    for entry in entries:  # StringStringEntryProto: key = 1, value = 2
                        kv = {number: _text(v) for number, v in _fields(entry)[1]}
                        if kv.get(1) == "location" and 2 in kv and kv[2] not in locations:
                            locations.append(kv[2])
                continue
            paths = _TENSOR_PATHS[kind]
            todo.extend((v, paths[number]) for number, v in reversed(nested) if number in paths)
    except ValueError:
        return [], []
    return names, locations


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
