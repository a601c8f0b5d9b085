"""``sdk.load`` and ``ShadingRatePredictor`` on the paths a user reaches with a damaged or foreign model, or a
splitting model used off its usual path: each refused with the SDK's own typed error, or the documented result.

The models are the shipped ``jnyang`` (planes in two graph inputs) and ``jnyang-reuse`` (it splits), edited
with ``onnx`` as ``tests/test_predictor.py`` edits them; a graph edit records the new digest, so that only the
edit is what the SDK sees.
"""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk


def _edited(tmp_path: Path, shipped: str, *, graph: Callable[[Any], None] | None = None,
            tail: Callable[[Any], None] | None = None, props: Callable[[dict[str, str]], None] | None = None) -> Path:
    """The shipped model ``shipped`` saved to ``tmp_path`` after ``graph`` edits its graph, ``tail`` its tail
    graph (``sdk.TAIL_KEY``) and ``props`` its ``metadata_props``; the metadata records the digests of the
    edited graphs (the edit is then the only thing wrong with the file)."""
    import onnx

    model = onnx.load(str(sdk.load(shipped).path))
    values = {p.key: p.value for p in model.metadata_props}
    meta = json.loads(values[sdk.METADATA_KEY])
    if graph is not None:
        graph(model.graph)
        meta["digest"] = sdk.model_digest(model.SerializeToString())  # the digest leaves metadata_props out
    if tail is not None:
        tail_model = onnx.load_from_string(base64.b64decode(values[sdk.TAIL_KEY]))
        tail(tail_model.graph)
        raw = tail_model.SerializeToString()
        values[sdk.TAIL_KEY] = base64.b64encode(raw).decode()
        meta["tail"] = sdk.model_digest(raw)
    values[sdk.METADATA_KEY] = json.dumps(meta)
    if props is not None:
        props(values)
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, values)
    path = tmp_path / f"edited-{shipped}.onnx"
    onnx.save(model, str(path))
    return path


@pytest.fixture(scope="module")
def reuse() -> sdk.ShadingRatePredictor:
    """The shipped splitting model."""
    return sdk.load("jnyang-reuse")


def _frame(pred: sdk.ShadingRatePredictor, h: int, w: int, seed: int = 1) -> np.ndarray:
    """A random frame for ``pred`` whose ``.tiles`` planes are those of its own luma planes."""
    names = pred.metadata.inputs
    x = np.random.default_rng(seed).random((len(names), h, w), dtype=np.float32)
    for c in pred.tail_inputs:
        x[names.index(c)] = sdk.tile_variances(x[names.index(c.removesuffix(".tiles"))])
    return x


# -- the model file ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("change", ["removed", "garbage"])
def test_a_model_file_that_changes_under_load_is_a_model_load_error(
    change: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The file is removed (an ``OSError``) or overwritten with bytes that are not ONNX (a ``ValueError`` from the
    digest) after onnxruntime built its session but before ``load`` read it back to check its digest (a re-export
    or a sync replacing it meanwhile): ``ModelLoadError`` saying the file cannot be read back, not a bare error
    and not ``ModelIntegrityError``."""
    from rtp.sdk import _predictor

    path = tmp_path / "jnyang.onnx"
    path.write_bytes(Path(sdk.load("jnyang").path or "").read_bytes())
    build = _predictor._session

    def session_then_change(*args: Any) -> Any:
        session = build(*args)
        if change == "removed":
            path.unlink()
        else:
            path.write_bytes(b"\x00not an onnx model")
        return session

    monkeypatch.setattr(_predictor, "_session", session_then_change)
    with pytest.raises(sdk.ModelLoadError, match=r"jnyang\.onnx'?: cannot be read back to check its digest") as info:
        sdk.load(path)
    assert type(info.value) is sdk.ModelLoadError
    assert isinstance(info.value.__cause__, OSError if change == "removed" else ValueError)


def test_a_model_whose_file_name_is_not_utf8_loads_from_its_bytes(tmp_path: Path) -> None:
    """A POSIX file name that is not valid UTF-8 (``b'\\xff.onnx'``, which Python reads as a str holding a lone
    surrogate): onnxruntime takes a path only as UTF-8 text and refused it with pybind's "incompatible constructor
    arguments"; ``load`` builds the session from the file's bytes instead, and predicts as the shipped model does."""
    import os

    shipped = sdk.load("jnyang")
    path = Path(os.fsdecode(os.fsencode(tmp_path) + b"/\xff.onnx"))
    try:
        path.write_bytes(Path(shipped.path or "").read_bytes())
    except (OSError, UnicodeError):  # a file system that takes only UTF-8 names
        pytest.skip("the file system refuses a file name that is not UTF-8")
    pred = sdk.load(path)
    assert pred.path == path
    x = np.random.default_rng(3).random((len(pred.metadata.inputs), 64, 96), dtype=np.float32)
    np.testing.assert_array_equal(pred.predict(x), shipped.predict(x))


def _jnyang_without_digest() -> Any:
    """The shipped ``jnyang`` as an onnx ModelProto whose metadata records no digest (as an adopted model's)."""
    import onnx

    model = onnx.load(str(sdk.load("jnyang").path))
    values = {p.key: p.value for p in model.metadata_props}
    meta = json.loads(values[sdk.METADATA_KEY])
    meta.pop("digest", None)
    values[sdk.METADATA_KEY] = json.dumps(meta)
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, values)
    return model


def test_a_model_with_external_data_whose_file_name_is_not_utf8_names_the_path(tmp_path: Path) -> None:
    """The same name on a model whose weights are stored beside it (ONNX external data, an adopted model that
    records no digest): onnxruntime finds those files only from the model's path, so it cannot load from the
    bytes: ``ModelLoadError`` saying the path is not UTF-8 and to rename the file, not pybind's message."""
    import os

    import onnx

    model = _jnyang_without_digest()
    path = Path(os.fsdecode(os.fsencode(tmp_path) + b"/\xff.onnx"))
    try:
        path.write_bytes(b"")
    except (OSError, UnicodeError):
        pytest.skip("the file system refuses a file name that is not UTF-8")
    onnx.save_model(model, str(path), save_as_external_data=True, location="weights.data", size_threshold=0)
    with pytest.raises(sdk.ModelLoadError, match=r"its path is not valid UTF-8 text.*external data.*rename the "
                                                r"file") as info:
        sdk.load(path)
    assert type(info.value) is sdk.ModelLoadError and "incompatible" not in str(info.value)


def _external_model(folder: Path, location: str, target: Path) -> Path:
    """The shipped ``jnyang`` without its digest (as an adopted model records none), its first weight stored in
    ``target`` and named by the ``location`` ``location`` (ONNX external data), saved as ``folder/model.onnx``."""
    import onnx
    from onnx import numpy_helper

    model = _jnyang_without_digest()
    tensor = model.graph.initializer[0]
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(numpy_helper.to_array(tensor).tobytes())
    tensor.ClearField("raw_data")
    tensor.ClearField("float_data")
    tensor.data_location = onnx.TensorProto.EXTERNAL
    for key, value in (("location", location), ("offset", "0"), ("length", str(target.stat().st_size))):
        entry = tensor.external_data.add()
        entry.key, entry.value = key, value
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "model.onnx"
    path.write_bytes(model.SerializeToString())
    return path


@pytest.mark.parametrize("how", ["dotdot", "absolute", "symlink"])
def test_external_data_outside_the_models_folder_is_refused_before_onnxruntime_reads_it(
        tmp_path: Path, how: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A model someone else made names a file outside its folder as its weights (``../secret/w.bin``, an absolute
    path, or a file beside it that is a symbolic link out of the folder): onnxruntime 1.17, which the SDK supports,
    read it (a model could make rtp read any file the user can); ``load`` refuses it with ``ModelLoadError`` naming
    the location, before any session is built, on every onnxruntime. A file inside the folder loads."""
    from rtp.sdk import _predictor

    secret = tmp_path / "secret" / "w.bin"
    folder = tmp_path / "models"
    if how == "symlink":
        folder.mkdir()
        try:
            (folder / "w.bin").symlink_to(secret)
        except OSError:
            pytest.skip("no symbolic links here")
    location = {"dotdot": "../secret/w.bin", "absolute": str(secret), "symlink": "w.bin"}[how]
    path = _external_model(folder, location, secret)
    built = []
    real = _predictor._session
    monkeypatch.setattr(_predictor, "_session", lambda *a, **k: built.append(a) or real(*a, **k))
    with pytest.raises(sdk.ModelLoadError, match=r"stored outside the \.onnx file \(ONNX external data\) in "
                                                  + re.escape(repr(location))) as info:
        sdk.load(path)
    assert type(info.value) is sdk.ModelLoadError and "inside the model's folder" in str(info.value)
    assert built == []  # (refused before onnxruntime saw the file)

    inside = _external_model(tmp_path / "ok", "w.bin", tmp_path / "ok" / "w.bin")
    assert sdk.load(inside).metadata.digest is None


def test_a_model_whose_inputs_disagree_on_their_size_is_refused(tmp_path: Path) -> None:
    """A model whose planes come in two graph inputs that name their height differently (a foreign exporter
    naming each input's axes by itself): the SDK cannot feed both from one frame, so ``load`` refuses it with
    ``MetadataError`` on ``inputs``, naming each input's shape."""

    def rename_height(graph: Any) -> None:
        graph.input[1].type.tensor_type.shape.dim[2].dim_param = "rows"

    path = _edited(tmp_path, "jnyang", graph=rename_height)
    with pytest.raises(sdk.MetadataError, match=r"the model's inputs disagree on batch, height or width: "
                                                r"\[\('input', \['batch', 5, 'height', 'width'\]\), "
                                                r"\('input\.5', \['batch', 4, 'rows', 'width'\]\)\]") as info:
        sdk.load(path)
    assert type(info.value) is sdk.MetadataError and info.value.key == "inputs"


# -- a splitting model's tail ----------------------------------------------------------------------------

def test_a_splitting_model_without_its_tail_entry_is_refused(tmp_path: Path) -> None:
    """``metadata.tail`` names a tail graph but the file's ``metadata_props`` lost the ``rtp.tail`` entry (a tool
    that rewrote the metadata and kept only ``rtp.metadata``): ``MetadataError`` on ``tail`` naming the key."""

    def drop_tail(values: dict[str, str]) -> None:
        del values[sdk.TAIL_KEY]

    path = _edited(tmp_path, "jnyang-reuse", props=drop_tail)
    with pytest.raises(sdk.MetadataError, match=r"tail: the metadata names a tail graph but .*edited-jnyang-reuse\.onnx"
                                                r"' holds no 'rtp\.tail' entry") as info:
        sdk.load(path)
    assert type(info.value) is sdk.MetadataError and info.value.key == "tail"


@pytest.mark.parametrize("text", ["not base64 at all!", "graph-\u00e9\u00e8", base64.b64encode(b"garbage\xff\xff").decode()],
                         ids=["not-base64", "not-ascii", "base64-not-onnx"])
def test_a_tail_entry_that_is_not_base64_onnx_is_a_model_load_error(text: str, tmp_path: Path) -> None:
    """The ``rtp.tail`` entry is damaged: not base64 (a ``binascii.Error``), not even ASCII, or base64 of bytes
    that are no ONNX protobuf (the digest's ``ValueError``): ``ModelLoadError`` saying the tail is not base64
    ONNX, before any digest is compared (not ``ModelIntegrityError``)."""

    def damage(values: dict[str, str]) -> None:
        values[sdk.TAIL_KEY] = text

    path = _edited(tmp_path, "jnyang-reuse", props=damage)
    with pytest.raises(sdk.ModelLoadError, match=r"its tail graph \(rtp\.tail\) is not base64 ONNX \(") as info:
        sdk.load(path)
    assert type(info.value) is sdk.ModelLoadError
    assert isinstance(info.value.__cause__, ValueError)  # binascii.Error is one


def test_a_splitting_model_without_its_features_output_is_refused(tmp_path: Path) -> None:
    """A model that splits (its tail loads) but whose graph no longer outputs the trunk's ``features`` (an
    optimiser that pruned the extra output): nothing can feed the tail, so ``load`` refuses it with
    ``MetadataError`` on ``tail``, naming the outputs it has."""

    def drop_features(graph: Any) -> None:
        keep = [o for o in graph.output if o.name != sdk.FEATURES_NAME]
        del graph.output[:]
        graph.output.extend(keep)

    path = _edited(tmp_path, "jnyang-reuse", graph=drop_features)
    with pytest.raises(sdk.MetadataError, match=r"tail: the model splits, but its outputs \['metric', 'finite_probe'\] "
                                                r"hold no 'features'") as info:
        sdk.load(path)
    assert type(info.value) is sdk.MetadataError and info.value.key == "tail"


@pytest.mark.parametrize("shape", [(1, 9, 64, 96), (64, 96), (2, 9, 64, 96)])
def test_the_split_methods_take_one_frame(reuse: sdk.ShadingRatePredictor, shape: tuple[int, ...]) -> None:
    """``predict_split`` and ``predict_tail`` work on one frame ``(C, H, W)``: a batch (even of one, which
    ``predict`` takes) or a single plane is ``InputShapeError`` naming the shape expected and the one given."""
    x = np.zeros(shape, np.float32)
    feats = np.zeros((16, 4, 6), np.float32)
    message = rf"expected one frame's inputs \(9, H, W\), got shape {re.escape(str(shape))}"
    for call in (lambda: reuse.predict_split(x), lambda: reuse.predict_tail(feats, x)):
        with pytest.raises(sdk.InputShapeError, match=message) as info:
            call()
        assert type(info.value) is sdk.InputShapeError
        assert info.value.actual == shape and info.value.expected == "(9, H, W)"


def _static_reuse(tmp_path: Path, h: int, w: int) -> sdk.ShadingRatePredictor:
    """The shipped splitting model exported for a fixed batch of one ``w x h`` frame (its tail unchanged)."""

    def fix_size(graph: Any) -> None:
        for i in graph.input:
            dims = i.type.tensor_type.shape.dim
            dims[0].dim_value, dims[2].dim_value, dims[3].dim_value = 1, h, w

    return sdk.load(_edited(tmp_path, "jnyang-reuse", graph=fix_size))


@pytest.mark.parametrize(("h", "w"), [(64, 96), (70, 100), (96, 96), (64, 160)])
def test_the_tail_on_a_frame_padded_past_its_last_tiles_repeats_the_last_features(tmp_path: Path, h: int, w: int) -> None:
    """A splitting model of a fixed input size (here 96x160: 6x10 tiles) takes a smaller frame padded up to that
    size, so the tail runs on more tile rows or columns than the frame has features for: ``predict_tail`` repeats
    the last row and column of features (as the frame's last row and column of pixels) and gives, cropped to the
    frame's tiles, what the tail gives on that padded frame with the features padded the same way."""
    pred = _static_reuse(tmp_path, 96, 160)
    assert pred.static_size == (96, 160) and pred.splits
    x = _frame(pred, h, w)
    est, feats = pred.predict_split(x)
    th, tw = pred.tiles(h, w)
    assert est.shape == (6, th, tw) and feats.shape == (16, th, tw)
    got = pred.predict_tail(feats, x)
    assert got.shape == (6, th, tw) and np.isfinite(got).all()
    frame = np.pad(x, ((0, 0), (0, 96 - h), (0, 160 - w)), mode="edge")
    features = np.pad(feats, ((0, 0), (0, 6 - th), (0, 10 - tw)), mode="edge")
    np.testing.assert_array_equal(got, pred.predict_tail(features, frame)[:, :th, :tw])


@pytest.mark.parametrize(("h", "w", "rows", "cols"), [(64, 96, [3], [5]), (96, 96, [], [5]), (64, 160, [3], []),
                                                    (96, 160, [], [])])
def test_the_tail_with_a_frames_own_features_gives_predict_but_at_a_fixed_size_models_padded_edge(
    tmp_path: Path, h: int, w: int, rows: list[int], cols: list[int]
) -> None:
    """``predict_tail`` with a frame's own features gives ``predict(x)`` (docs/runtime.md), except, as
    documented, on a model of a fixed input size given a smaller frame: the trunk's features of the
    padded tiles are not kept, so the last tile row (a frame of fewer tile rows) and column (fewer
    columns) differ; a frame of the model's size is exact."""
    pred = _static_reuse(tmp_path, 96, 160)
    x = _frame(pred, h, w)
    est, feats = pred.predict_split(x)
    differ = np.abs(pred.predict_tail(feats, x) - est).max(axis=0) > 1e-5
    assert [r for r in range(differ.shape[0]) if differ[r].all()] == rows
    assert [c for c in range(differ.shape[1]) if differ[:, c].all()] == cols
    differ[rows, :] = False
    differ[:, cols] = False
    assert not differ.any()  # everywhere else what predict gives


def test_onnxruntime_failing_on_the_tail_is_an_inference_error(reuse: sdk.ShadingRatePredictor, tmp_path: Path) -> None:
    """A splitting model whose tail declares no fixed number of feature channels (a foreign exporter), given the
    features of another trunk: the SDK cannot check their channels, onnxruntime fails on the tail, and
    ``predict_tail`` raises ``InferenceError`` naming the tail and the shapes fed, not onnxruntime's bare error."""

    def any_channels(graph: Any) -> None:
        feats = next(i for i in graph.input if i.name == sdk.FEATURES_NAME)
        feats.type.tensor_type.shape.dim[1].dim_param = "channels"

    pred = sdk.load(_edited(tmp_path, "jnyang-reuse", tail=any_channels))
    x = _frame(pred, 64, 96)
    _, feats = pred.predict_split(x)
    np.testing.assert_array_equal(pred.predict_tail(feats, x), reuse.predict_tail(feats, x))  # right features: as shipped
    with pytest.raises(sdk.InferenceError, match=r"onnxruntime failed on the tail, features \(1, 3, 4, 6\) and input "
                                                 r"\(1, 9, 64, 96\): ") as info:
        pred.predict_tail(feats[:3], x)
    assert type(info.value) is sdk.InferenceError and info.value.__cause__ is not None
