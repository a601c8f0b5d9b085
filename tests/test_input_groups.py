"""Input planes in groups: rtp-export gives a model of more than seven planes several graph inputs of at
most seven consecutive planes (onnxruntime's blocked convolution then reads each where it lies on an
AVX2 CPU), and rtp.sdk feeds each its planes as views of the one array it is given."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from onnx import helper

from rtp import export, sdk
from rtp.train import checkpoint

from .conftest import base_metadata, split_model, trained_like_fast_net

NINE = ["reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "metallic", "specular", "reprojected.y.blocks",
        "albedo.y.blocks"]


@pytest.fixture(scope="module")
def nine_pt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """rtp's fast network on the shipped JNYang's nine planes, trained-like BatchNorm, as a checkpoint."""
    return checkpoint.save(tmp_path_factory.mktemp("groups") / "nine.pt", trained_like_fast_net(9, seed=4),
                           base_metadata(inputs=NINE))


def _graph_inputs(path: Path) -> list[tuple[str, int]]:
    return [(i.name, i.type.tensor_type.shape.dim[1].dim_value) for i in onnx.load(str(path)).graph.input]


def test_nine_planes_export_in_two_inputs_and_predict_as_one(nine_pt: Path, tmp_path: Path) -> None:
    grouped = export.export_checkpoint(nine_pt, tmp_path / "grouped.onnx")
    whole = export.export_checkpoint(nine_pt, tmp_path / "whole.onnx", split_planes=False)
    assert _graph_inputs(grouped) == [("input", 5), ("input.5", 4)]
    assert _graph_inputs(whole) == [("input", 9)]
    a, b = sdk.load(grouped), sdk.load(whole)
    assert a.graph_inputs == (("input", tuple(NINE[:5])), ("input.5", tuple(NINE[5:])))
    assert b.graph_inputs == (("input", tuple(NINE)),)
    x = np.random.default_rng(0).random((9, 75, 130), dtype=np.float32)  # partial tiles, padded rows and columns
    np.testing.assert_allclose(a.predict(x), b.predict(x), rtol=1e-5, atol=1e-6)
    assert not np.array_equal(a.predict_raw(x), np.zeros_like(a.predict_raw(x)))
    # the stem's group convolutions are summed by one Sum, which keeps the name the stem's output had
    nodes = onnx.load(str(grouped)).graph.node
    sums = [n for n in nodes if n.op_type == "Sum"]
    assert len(sums) == 1 and sums[0].output[0] in {n.output[0] for n in onnx.load(str(whole)).graph.node}


def _recording(pred: sdk.ShadingRatePredictor) -> tuple[list[dict[str, np.ndarray]], Any]:
    """Swap ``pred``'s session for one that records what each run is fed: (the feeds, the real session)."""
    fed: list[dict[str, np.ndarray]] = []
    real = pred._session

    class Recording:
        def __getattr__(self, name: str) -> object:
            return getattr(real, name)

        def run(self, names: list[str], feed: dict[str, np.ndarray]) -> list[np.ndarray]:
            fed.append(feed)
            return real.run(names, feed)

    pred._session = Recording()
    return fed, real


def test_predict_feeds_each_input_a_view_of_the_frame(nine_pt: Path, tmp_path: Path) -> None:
    """No copy for a frame that needs no padding: each input is a slice of the caller's planes."""
    pred = sdk.load(export.export_checkpoint(nine_pt, tmp_path / "g.onnx"))
    fed, _ = _recording(pred)
    x = np.random.default_rng(1).random((9, 64, 96), dtype=np.float32)
    pred.predict(x)
    assert [(k, v.shape) for k, v in fed[0].items()] == [("input", (1, 5, 64, 96)), ("input.5", (1, 4, 64, 96))]
    assert all(np.shares_memory(v, x) for v in fed[0].values())


def test_a_batch_runs_frame_by_frame_on_views(nine_pt: Path, tmp_path: Path) -> None:
    """A batch's groups would be copies (a frame's planes of one group are not next to the next frame's),
    so a grouped model runs a batch one frame at a time on views: the same values as one run on copies."""
    pred = sdk.load(export.export_checkpoint(nine_pt, tmp_path / "g.onnx"))
    fed, real = _recording(pred)
    x = np.random.default_rng(2).random((3, 9, 64, 96), dtype=np.float32)
    batched = pred.predict(x)
    assert len(fed) == 3
    for i, feed in enumerate(fed):
        assert [v.shape for v in feed.values()] == [(1, 5, 64, 96), (1, 4, 64, 96)]
        assert all(np.shares_memory(v, x[i]) for v in feed.values())
    one_run = real.run([pred._out_name], {"input": np.ascontiguousarray(x[:, :5]), "input.5": np.ascontiguousarray(x[:, 5:])})
    np.testing.assert_allclose(pred.predict_raw(x), one_run[0][:, :, :4, :6], rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(batched[1], pred.predict(x[1]))


@pytest.mark.parametrize("plane", [0, 4, 5, 8])
def test_a_nan_in_either_group_is_refused_by_the_probe(nine_pt: Path, tmp_path: Path, plane: int) -> None:
    pred = sdk.load(export.export_checkpoint(nine_pt, tmp_path / "g.onnx"))
    assert pred.metadata.finite_probe == "finite_probe"
    x = np.random.default_rng(2).random((9, 32, 48), dtype=np.float32)
    x[plane, 17, 33] = np.nan
    with pytest.raises(sdk.NonFiniteInputError, match=re.escape(f"first at index (0, {plane}, 17, 33)")):
        pred.predict(x)


def test_restamp_splits_a_model_of_one_input_and_keeps_its_predictions(nine_pt: Path, tmp_path: Path) -> None:
    path = export.export_checkpoint(nine_pt, tmp_path / "old.onnx", split_planes=False)
    x = np.random.default_rng(3).random((9, 64, 80), dtype=np.float32)
    before = sdk.load(path).predict_raw(x)
    export.restamp(path)
    assert _graph_inputs(path) == [("input", 5), ("input.5", 4)]
    after = sdk.load(path)
    assert after.metadata.digest == sdk.model_digest(path.read_bytes())
    np.testing.assert_allclose(after.predict_raw(x), before, rtol=1e-5, atol=1e-6)
    once = path.read_bytes()
    export.restamp(path)  # already in groups: nothing to change but the bytes of the same graph
    np.testing.assert_array_equal(sdk.load(path).predict_raw(x), after.predict_raw(x))
    assert _graph_inputs(path) == [("input", 5), ("input.5", 4)] and len(path.read_bytes()) == len(once)


def test_the_cli_keeps_one_input_when_asked(nine_pt: Path, tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "rtp.cli.export"]
    out = subprocess.run([*cmd, str(nine_pt), "-o", str(tmp_path / "one.onnx"), "--one-input"], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr
    assert _graph_inputs(tmp_path / "one.onnx") == [("input", 9)]
    bad = subprocess.run([*cmd, "--restamp", str(tmp_path / "one.onnx"), "--one-input"], capture_output=True, text=True)
    assert bad.returncode == 2 and "takes no other options" in bad.stderr


def test_join_planes_gives_back_the_one_input_model(nine_pt: Path, tmp_path: Path) -> None:
    """``rtp-export --join-planes`` (``export.join_input_planes``) undoes the groups of an exported file: one
    input of nine planes, one stem convolution, the predictions of the checkpoint exported with
    ``--one-input`` to the bit, the probe still refusing a NaN in any plane, the metadata kept."""
    grouped = export.export_checkpoint(nine_pt, tmp_path / "grouped.onnx")
    whole = sdk.load(export.export_checkpoint(nine_pt, tmp_path / "whole.onnx", split_planes=False))
    cmd = [sys.executable, "-m", "rtp.cli.export"]
    out = subprocess.run([*cmd, "--join-planes", str(grouped), "-o", str(tmp_path / "joined.onnx")],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    joined = sdk.load(tmp_path / "joined.onnx")
    assert _graph_inputs(tmp_path / "joined.onnx") == [("input", 9)]
    assert joined.graph_inputs == (("input", tuple(NINE)),)
    graph = onnx.load(str(tmp_path / "joined.onnx")).graph
    assert not [n for n in graph.node if n.op_type == "Sum"]
    assert {n.op_type for n in graph.node} == {n.op_type for n in onnx.load(str(tmp_path / "whole.onnx")).graph.node}
    x = np.random.default_rng(5).random((9, 75, 130), dtype=np.float32)
    np.testing.assert_array_equal(joined.predict_raw(x), whole.predict_raw(x))
    assert joined.metadata.to_dict() | {"digest": None} == sdk.load(grouped).metadata.to_dict() | {"digest": None}
    for plane in (0, 8):
        bad = x.copy()
        bad[plane, 3, 4] = np.nan
        with pytest.raises(sdk.NonFiniteInputError):
            joined.predict(bad)
    with pytest.raises(sdk.ParameterError, match="in one input already"):
        export.join_input_planes(tmp_path / "joined.onnx", tmp_path / "again.onnx")
    assert not (tmp_path / "again.onnx").exists()
    for args, message in (([str(grouped)], "needs -o OUTPUT.onnx"),
                          ([str(grouped), "-o", "x.onnx", "--strip-probe", str(grouped)], "takes only -o")):
        bad_cli = subprocess.run([*cmd, "--join-planes", *args], capture_output=True, text=True, cwd=tmp_path)
        assert bad_cli.returncode == 2 and message in bad_cli.stderr, bad_cli.stderr


def test_planes_only_the_tile_contrast_reads_come_in_a_group_the_stem_does_not_read(tmp_path: Path) -> None:
    """A split network's stem weighs its ``.tiles`` planes zero and its tile contrast reads nothing else:
    the planes come in 7 + 2 inputs, each convolution reads only its own, the predictions and the split
    path's are the one-input export's, the probe still refuses a NaN anywhere (a pixel the contrast never
    reads too), and joining gives back the one-input graph to the bit."""
    grouped = split_model(tmp_path, "tiles")
    whole = sdk.load(export.export_checkpoint(tmp_path / "split-tiles.pt", tmp_path / "whole.onnx", split_planes=False))
    assert _graph_inputs(grouped) == [("input", 7), ("input.7", 2)]
    graph = onnx.load(str(grouped)).graph
    convs = {n.output[0]: n.input[0] for n in graph.node if n.op_type == "Conv" and n.input[0].startswith("input")}
    assert sorted(convs.values()) == ["input", "input.7"] and not [n for n in graph.node if n.name.endswith("planes_sum1")]
    pred = sdk.load(grouped)
    x = np.random.default_rng(6).random((9, 64, 96), dtype=np.float32)
    x[7:] = sdk.tile_variances(x[0])[None]
    np.testing.assert_allclose(pred.predict_raw(x), whole.predict_raw(x), rtol=1e-5, atol=1e-6)
    errors, feats = pred.predict_split(x)
    np.testing.assert_allclose(feats, whole.predict_split(x)[1], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(pred.predict_tail(feats, x), errors, rtol=1e-5, atol=1e-6)
    for plane, y, xx in ((3, 40, 50), (8, 5, 9), (7, 63, 95)):  # (5, 9) and (63, 95): pixels the contrast skips
        bad = x.copy()
        bad[plane, y, xx] = np.inf
        with pytest.raises(sdk.NonFiniteInputError):
            pred.predict(bad)
    joined = sdk.load(export.join_input_planes(grouped, tmp_path / "joined.onnx"))
    assert joined.graph_inputs == (("input", tuple(whole.metadata.inputs)),)
    np.testing.assert_array_equal(joined.predict_raw(x), whole.predict_raw(x))
    export.restamp(tmp_path / "joined.onnx")  # back to today's groups
    assert _graph_inputs(tmp_path / "joined.onnx") == [("input", 7), ("input.7", 2)]
    np.testing.assert_allclose(sdk.load(tmp_path / "joined.onnx").predict_raw(x), whole.predict_raw(x), rtol=1e-5,
                               atol=1e-6)


def test_join_planes_refuses_inputs_rtp_export_did_not_split(tmp_path: Path) -> None:
    """Inputs named otherwise than ``input``, ``input.K`` (K the first plane of the group) are not
    rtp-export's groups: a typed error, nothing written."""
    path = _grouped_model(tmp_path, [5, 4], 9)  # input, input.1: not input, input.5
    with pytest.raises(export.ExportError, match="not planes in groups"):
        export.join_input_planes(path, tmp_path / "joined.onnx")
    assert not (tmp_path / "joined.onnx").exists()


def _graph(c: int, reader: str = "Conv") -> onnx.ModelProto:
    w = helper.make_tensor("w", onnx.TensorProto.FLOAT, [2, c, 4, 4], np.ones(2 * c * 16, np.float32))
    node = (helper.make_node("Conv", ["input", "w"], ["metric"], kernel_shape=[4, 4], strides=[4, 4]) if reader == "Conv"
            else helper.make_node("Relu", ["input"], ["metric"]))
    out_c = 2 if reader == "Conv" else c
    graph = helper.make_graph([node], "g", [helper.make_tensor_value_info("input", onnx.TensorProto.FLOAT,
                                                                          ["batch", c, "height", "width"])],
                              [helper.make_tensor_value_info("metric", onnx.TensorProto.FLOAT,
                                                             ["batch", out_c, "th", "tw"])], [w])
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


@pytest.mark.parametrize(("planes", "sizes"), [(7, [7]), (8, [4, 4]), (9, [5, 4]), (12, [6, 6]), (15, [5, 5, 5]),
                                               (16, [6, 5, 5])])
def test_groups_are_as_few_and_as_even_as_can_be(planes: int, sizes: list[int]) -> None:
    import onnxruntime as ort

    model = _graph(planes)
    x = np.random.default_rng(planes).random((1, planes, 16, 24), dtype=np.float32)
    want = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"input": x})[0]
    assert export.split_input_planes(model) == len(sizes)
    onnx.checker.check_model(model, full_check=True)
    got_sizes = [i.type.tensor_type.shape.dim[1].dim_value for i in model.graph.input]
    assert got_sizes == sizes and max(sizes) <= export.PLANES_PER_INPUT
    ends = np.cumsum([0, *sizes])
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    feed = {i.name: x[:, a:b] for i, a, b in zip(session.get_inputs(), ends[:-1], ends[1:])}
    np.testing.assert_allclose(session.run(None, feed)[0], want, rtol=1e-5)


def _zero_plane_graph(planes: int, dead: list[list[bool]]) -> onnx.ModelProto:
    """A stem (4x4, stride 4, every pixel once) and ``len(dead) - 1`` tile readers (3x4, stride 16) of the
    same planes, weights zero on the planes ``dead[k]`` marks, pooled to the tile grid and concatenated,
    with rtp's finite probe on the stem."""
    rng = np.random.default_rng(planes + 10 * len(dead))
    inits, nodes, outs = [], [], []
    for k, zero in enumerate(dead):
        kernel, stride = ((4, 4), 4) if k == 0 else ((3, 4), 16)
        w = rng.standard_normal((3, planes, *kernel)).astype(np.float32)
        w[:, np.array(zero, bool)] = 0.0
        inits.append(helper.make_tensor(f"w{k}", onnx.TensorProto.FLOAT, w.shape, w.ravel()))
        nodes.append(helper.make_node("Conv", ["input", f"w{k}"], [f"c{k}"], kernel_shape=list(kernel),
                                      strides=[stride, stride], name=f"conv{k}"))
        if k == 0:
            nodes.append(helper.make_node("MaxPool", ["c0"], ["p0"], kernel_shape=[4, 4], strides=[4, 4]))
        outs.append("p0" if k == 0 else f"c{k}")
    nodes.append(helper.make_node("Concat", outs, ["metric"], axis=1))
    graph = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("input", onnx.TensorProto.FLOAT,
                                                                         [1, planes, "h", "w"])],
                              [helper.make_tensor_value_info("metric", onnx.TensorProto.FLOAT,
                                                             [1, 3 * len(dead), "th", "tw"])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    assert export.add_finite_probe(model, 16) == "finite_probe"
    return model


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 12).flatmap(lambda c: st.lists(st.lists(st.booleans(), min_size=c, max_size=c),
                                                      min_size=1, max_size=3)))
def test_groups_follow_the_planes_each_convolution_reads(dead: list[list[bool]]) -> None:
    """Any pattern of planes the convolutions weigh zero: after the split each convolution reads the groups
    holding planes it weighs and no other (but groups of planes none weighs), no group holds more than
    seven, the outputs are the one-input graph's within float rounding, a NaN in any plane reaches the
    probe, and joining gives back the one-input graph's outputs to the bit."""

    import onnxruntime as ort

    planes = len(dead[0])
    model = _zero_plane_graph(planes, dead)
    run = lambda m, feed: ort.InferenceSession(m.SerializeToString(),  # noqa: E731
                                               providers=["CPUExecutionProvider"]).run(None, feed)
    x = np.random.default_rng(planes).random((1, planes, 32, 48), dtype=np.float32)
    want = run(model, {"input": x})
    split = onnx.ModelProto()
    split.CopyFrom(model)
    export.split_input_planes(split)
    onnx.checker.check_model(split, full_check=True)
    groups = [(i.name, i.type.tensor_type.shape.dim[1].dim_value) for i in split.graph.input]
    starts = np.cumsum([0] + [n for _, n in groups])
    assert starts[-1] == planes and max(n for _, n in groups) <= export.PLANES_PER_INPUT
    feed = lambda a: {name: a[:, s:s + n] for (name, n), s in zip(groups, starts)}  # noqa: E731
    unweighed = {name for (name, n), s in zip(groups, starts) if all(all(z[s:s + n]) for z in dead)}
    for k, zero in enumerate(dead):  # planes no convolution weighs ride with a neighbouring group's readers
        read = {n.input[0] for n in split.graph.node if n.op_type == "Conv" and n.name.startswith(f"conv{k}")}
        weighed = {name for (name, n), s in zip(groups, starts) if not all(zero[s:s + n])}
        if weighed:
            assert weighed <= read <= weighed | unweighed, (k, read, weighed)
        else:  # a convolution of zeros reads the first group
            assert read == {"input"}, (k, read)
    got = run(split, feed(x))
    np.testing.assert_allclose(got[0], want[0], rtol=1e-5, atol=1e-5)
    for plane in range(planes):
        bad = x.copy()
        bad[0, plane, 31, 47] = np.nan
        assert not np.isfinite(run(split, feed(bad))[1]), plane
    export._export._join_groups(split)
    np.testing.assert_array_equal(run(split, {"input": x})[0], want[0])


def test_a_graph_whose_planes_another_op_reads_is_left_whole() -> None:
    model = _graph(9, reader="Relu")
    before = model.SerializeToString()
    assert export.split_input_planes(model) == 1
    assert model.SerializeToString() == before


def _grouped_model(tmp_path: Path, sizes: list[int | str], planes: int) -> Path:
    """A graph whose input planes come in inputs of ``sizes`` planes, with rtp metadata of ``planes`` planes."""
    inputs, nodes, parts = [], [], []
    for g, n in enumerate(sizes):
        name = "input" if g == 0 else f"input.{g}"
        inputs.append(helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, [1, n, "h", "w"]))
        k = n if isinstance(n, int) else 1
        w = helper.make_tensor(f"w{g}", onnx.TensorProto.FLOAT, [6, k, 16, 16], np.ones(6 * k * 256, np.float32))
        nodes.append(helper.make_node("Conv", [name, f"w{g}"], [f"c{g}"], kernel_shape=[16, 16], strides=[16, 16]))
        parts.append((f"c{g}", w))
    nodes.append(helper.make_node("Sum", [p for p, _ in parts], ["metric"]))
    graph = helper.make_graph(nodes, "g", inputs, [helper.make_tensor_value_info("metric", onnx.TensorProto.FLOAT,
                                                                                 [1, 6, "th", "tw"])],
                              [w for _, w in parts])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    meta = base_metadata(inputs=NINE[:planes], outputs=["1x2", "2x1", "2x2", "2x4", "4x2", "4x4"])
    export.write_metadata(model, sdk.ModelMetadata.from_dict(meta))
    path = tmp_path / "grouped.onnx"
    onnx.save(model, str(path))
    return path


def test_inputs_that_do_not_add_up_to_the_planes_are_refused(tmp_path: Path) -> None:
    with pytest.raises(sdk.MetadataError, match=r"metadata declares 9 channels .* hold 5 \+ 3 \(input, input.1\)"):
        sdk.load(_grouped_model(tmp_path, [5, 3], 9))
    ok = sdk.load(_grouped_model(tmp_path, [5, 4], 9))
    assert [n for n, _ in ok.graph_inputs] == ["input", "input.1"]
    x = np.ones((9, 32, 32), np.float32)
    np.testing.assert_allclose(ok.predict_raw(x), 9 * 256, rtol=1e-6)  # every plane reached its input


def test_inputs_without_a_fixed_number_of_planes_are_refused(tmp_path: Path) -> None:
    with pytest.raises(sdk.MetadataError, match="must give each a fixed number of planes"):
        sdk.load(_grouped_model(tmp_path, [5, "c"], 9))


def test_bench_same_decisions_reads_a_dataset_and_refuses_two_models(nine_pt: Path, tmp_path: Path) -> None:
    from .test_train import _dataset

    data = _dataset(tmp_path / "ds", n=3)
    grouped = export.export_checkpoint(nine_pt, tmp_path / "grouped.onnx")
    whole = export.export_checkpoint(nine_pt, tmp_path / "whole.onnx", split_planes=False)
    script = Path(__file__).resolve().parents[1] / "bench" / "same_decisions.py"
    out = subprocess.run([sys.executable, str(script), str(whole), str(grouped), "--data", str(data)],
                         capture_output=True, text=True, check=True).stdout
    assert "3 samples" in out
    raw, est, differ = [c.strip() for c in out.strip().splitlines()[-1].strip("|").split("|")]
    assert 0.0 <= float(raw) < 1e-5 and float(est) < 1e-4
    assert [int(v) for v in differ.split(" / ")] == [0, 0, 0]
    bad = subprocess.run([sys.executable, str(script), "lpips", str(grouped), "--data", str(data)],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "not one model" in bad.stderr
