"""Model integrity: rtp-export records a digest of graph and weights; sdk.load refuses a file whose
graph or weights changed, including a single bit flipped anywhere in a shipped model's weights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import pytest

from rtp import sdk
from rtp.export import restamp, write_metadata

from .conftest import base_metadata, build_onnx

SHIPPED = sdk.shipped_models()


def _weight_spans(data: bytes, model: onnx.ModelProto) -> list[tuple[str, int, int]]:
    """(initializer name, start, end) of every initializer's raw bytes in the serialized file."""
    spans = []
    for init in model.graph.initializer:
        raw = init.raw_data or onnx.numpy_helper.to_array(init).tobytes()
        start = data.find(raw) if init.raw_data else -1
        if start >= 0 and len(raw) > 0:
            spans.append((init.name, start, start + len(raw)))
    return spans


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_models_record_their_digest_and_load(name: str) -> None:
    meta = sdk.load(name).metadata
    assert meta.digest is not None and meta.digest.startswith("sha256:")
    data = (Path(sdk.load(name).path)).read_bytes()
    assert sdk.model_digest(data) == meta.digest


@pytest.mark.parametrize("name", SHIPPED)
def test_a_bit_flip_anywhere_in_the_weights_is_refused(name: str, tmp_path: Path) -> None:
    path = Path(sdk.load(name).path)
    data = path.read_bytes()
    spans = _weight_spans(data, onnx.load_from_string(data))
    assert spans, "no initializer bytes found"
    rng = np.random.default_rng(0)
    tried = 0
    for init_name, start, end in spans:
        # every initializer: its first and last byte and a few in between, each with a random bit
        for pos in {start, end - 1, *rng.integers(start, end, size=3).tolist()}:
            bad = bytearray(data)
            bad[pos] ^= 1 << int(rng.integers(8))
            target = tmp_path / f"{name}-{pos}.onnx"
            target.write_bytes(bytes(bad))
            with pytest.raises(sdk.ModelLoadError) as err:
                sdk.load(target)
            assert isinstance(err.value, sdk.ModelIntegrityError), (init_name, pos, err.value)
            assert "differ from what was exported" in str(err.value)
            tried += 1
    assert tried >= 2 * len(spans)


def test_metadata_changes_keep_the_digest_and_graph_changes_break_it(tmp_path: Path) -> None:
    path = build_onnx(tmp_path / "m.onnx", weights=np.eye(4, dtype=np.float32), metadata=None)
    model = onnx.load(str(path))
    write_metadata(model, sdk.ModelMetadata.from_dict(base_metadata()))
    onnx.save(model, str(path))
    meta = sdk.load(path).metadata
    assert meta.digest == sdk.model_digest(path.read_bytes())
    # another metadata entry (a foreign key) leaves the digest valid
    onnx.helper.set_model_props(model, {**{p.key: p.value for p in model.metadata_props}, "vendor": "x"})
    onnx.save(model, str(path))
    sdk.load(path)
    # a changed doc string (outside metadata_props) is a changed model
    model.doc_string = "edited"
    onnx.save(model, str(path))
    with pytest.raises(sdk.ModelIntegrityError):
        sdk.load(path)


def test_models_without_a_digest_load_with_a_note(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = build_onnx(tmp_path / "old.onnx", weights=np.eye(4, dtype=np.float32), metadata=base_metadata())
    with caplog.at_level("INFO", logger="rtp"):
        pred = sdk.load(path)
    assert pred.metadata.digest is None and "integrity not checked" in caplog.text
    x = np.random.default_rng(1).random((4, 32, 48), dtype=np.float32)
    before = pred.predict_raw(x)
    restamp(path)
    again = sdk.load(path)
    assert again.metadata.digest == sdk.model_digest(path.read_bytes())
    np.testing.assert_array_equal(again.predict_raw(x), before)


def test_malformed_digests_are_refused() -> None:
    for bad in ("md5:abc", "sha256:" + "g" * 64, 42, "sha256:" + "a" * 63):
        with pytest.raises(sdk.MetadataError, match="digest"):
            sdk.ModelMetadata.from_dict({**base_metadata(), "digest": bad})
    with pytest.raises(ValueError):
        sdk.model_digest(b"\xff\xff\xff\xff")


def test_the_digest_skips_exactly_the_metadata_entries_of_any_wire_type() -> None:
    """model_digest walks the protobuf wire format itself (the runtime has no onnx package): every
    top-level field but metadata_props (14) is hashed, whatever its wire type (varint, fixed64,
    length-delimited, fixed32), and malformed bytes are a ParameterError naming the fault."""
    import hashlib

    kept = (b"\x08\x96\x01"  # field 1, varint 150
            + b"\x11" + bytes(range(8))  # field 2, fixed64
            + b"\x22\x02xy"  # field 4, 2 bytes
            + b"\x1d" + b"\x01\x02\x03\x04")  # field 3, fixed32 (a metadata entry right after it)
    meta = b"\x72\x03abc"  # field 14: metadata_props, dropped wherever it stands
    data = meta + kept[:3] + meta + kept[3:] + meta
    assert sdk.model_digest(data) == "sha256:" + hashlib.sha256(kept).hexdigest()
    assert sdk.model_digest(bytearray(data)) == sdk.model_digest(memoryview(kept))
    for bad, why in ((b"\x00\x01", "field number 0"), (b"\x0b", "unsupported wire type 3"),
                     (b"\x22\x05ab", "truncated field"), (b"\x11\x00\x00", "truncated field"),
                     (b"\x1d\x00", "truncated field"), (b"\x08\x80", "truncated or malformed varint")):
        with pytest.raises(sdk.ParameterError, match=f"not the bytes of an ONNX model \\({why}\\)"):
            sdk.model_digest(bad)
    with pytest.raises(sdk.ParameterError, match="expected the bytes of an ONNX model, got str"):
        sdk.model_digest("model.onnx")  # type: ignore[arg-type]


def test_a_model_resaved_with_external_data_is_named_with_how_to_resave_it(tmp_path: Path) -> None:
    """onnx.save_model(..., save_as_external_data=True) moves the weights into a file beside the model: its digest
    cannot match, and the error said "modified after export". It says where the weights went and how to re-save
    the model with them inside; done as it says, the model loads with its exported digest again."""
    original = Path(sdk.load("jnyang").path)
    path = tmp_path / "ext.onnx"
    onnx.save_model(onnx.load(str(original)), str(path), save_as_external_data=True, location="ext.onnx.data")
    assert (tmp_path / "ext.onnx.data").is_file()
    with pytest.raises(sdk.ModelIntegrityError) as err:
        sdk.load(path)
    text = str(err.value)
    assert "its weights are stored outside the .onnx file (ONNX external data:" in text, text
    assert "'ext.onnx.data'" in text and "save_as_external_data=True" in text
    assert f"m = onnx.load({str(path)!r})" in text and f"onnx.save_model(m, {str(path)!r})" in text
    assert "t.ClearField('data_location')" in text
    assert "modified after export" not in text
    # the recipe of the message: every tensor inside, the exported bytes' digest again
    model = onnx.load(str(path))
    for t in model.graph.initializer:
        t.ClearField("data_location")
    onnx.save_model(model, str(path))
    (tmp_path / "ext.onnx.data").unlink()
    assert sdk.load(path).metadata.digest == sdk.model_digest(path.read_bytes()) == sdk.load("jnyang").metadata.digest
    # a model holding its tensors has none outside, nor do bytes of no model
    from rtp.sdk._digest import external_tensors

    assert external_tensors(original.read_bytes()) == ([], []) and external_tensors(b"\xff\xff junk") == ([], [])
