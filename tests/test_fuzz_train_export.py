"""Property-based fuzzing of rtp.train and rtp.export (hypothesis), in the style of
tests/test_fuzz_rooms.py: whatever malformed configuration, recipe, checkpoint file, network argument,
model path, metadata mapping or option arrives, a public function either returns or refuses it with an
rtp.sdk.RtpError (docs/errors.md); no bare numpy, torch, onnx, yaml or pathlib exception escapes and no
call hangs.

Only cases that fail fast: ``train`` gets a data folder that does not exist (every configuration must be
refused before any step; one that returns is absurd), networks are a few channels wide and the values
that size a network are drawn either small or not counts at all.
"""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
import yaml
from hypothesis import strategies as st

from rtp import export as X
from rtp import sdk
from rtp import train as T
from rtp.train import checkpoint as C
from rtp.train.model import build_network

from .fuzzing import (
    Target,
    _array,
    arrays,
    fuzz_bounded,
    hostile_numbers,
    json_scalars,
    json_values,
    scratch_folder,
    small_or_absurd,
)

_WORK = scratch_folder("rtp-fuzz-train-export-")


@pytest.fixture(autouse=True, scope="module")
def _in_scratch() -> Any:
    """Drawn text is a valid relative output path too: the exports write it inside the scratch folder,
    not into the checkout the tests run from."""
    with contextlib.chdir(_WORK):
        yield


hostile_counts = hostile_numbers.filter(small_or_absurd)
_counter = iter(range(10**9))


def _fresh(name: str) -> Path:
    d = _WORK / f"{name}{next(_counter)}"
    d.mkdir()
    return d


#: Paths that are not what a function takes: missing, a folder, an empty or junk file, a NUL, not a path.
_PATH_KINDS = ["missing", "folder", "empty", "junk", "nul", "none", "int", "list", "bytes", "yaml"]
path_kinds = st.one_of(st.sampled_from(_PATH_KINDS), json_scalars)


#: An integer stands for a descriptor that is not open: ``open(1)`` would read, then close, pytest's stdout.
_NO_FD = 987_654


def _path(kind: Any) -> Any:
    if isinstance(kind, (int, np.integer)):
        return _NO_FD
    if not isinstance(kind, str) or kind not in _PATH_KINDS:
        return kind
    d = _fresh("p")
    return {"missing": lambda: d / "nope" / "x.onnx", "folder": lambda: d, "nul": lambda: str(d / "a\0b"),
            "none": lambda: None, "int": lambda: _NO_FD, "list": lambda: [str(d)], "bytes": lambda: str(d).encode(),
            "empty": lambda: _write(d / "e.onnx", b""), "junk": lambda: _write(d / "j.onnx", b"\x08\x01junk\xff" * 9),
            "yaml": lambda: _write(d / "m.yaml", b"metric: jnyang\n")}[kind]()


def _write(p: Path, data: bytes) -> Path:
    p.write_bytes(data)
    return p


# -- rtp.train: TrainConfig and train ----------------------------------------------------------

_META = {"metric": "jnyang", "transform": {"type": "clamped", "mu_y": 0.25}, "tile_size": 16,
         "inputs": list(sdk.DEFAULT_INPUTS), "outputs": list(sdk.DEFAULT_OUTPUTS), "default_threshold": 0.25,
         "weber_l": 0.02, "safety": 0.05}
_CFG_VALID: dict[str, st.SearchStrategy[Any]] = {
    "tile": st.sampled_from([8, 16]), "arch": st.sampled_from(["paper", "fast"]), "width": st.sampled_from([2, 4]),
    "steps": st.integers(1, 3), "batch": st.integers(1, 2), "crop": st.sampled_from([16, 32]),
    "lr": st.floats(1e-5, 1e-2), "loss": st.sampled_from(["l1", "mse", "quantile"]), "seed": st.integers(0, 5),
}
_CFG_FIELDS = ["metric", "tile", "outputs", "inputs", "transform", "logistic_k", "arch", "width", "head", "depth",
               "stem", "grow", "max_width", "separable", "tail_width", "head_width", "context_pool", "coarse",
               "coarse_width", "block_contrast", "contrast_cell", "contrast_max", "stem_layers", "augment", "mirror",
               "loss", "quantile", "focus", "ema", "teachers", "distill", "aux_metrics", "aux_weight", "steps", "batch",
               "crop", "context", "lr", "lr_decay", "optimizer", "schedule", "weight_decay", "val_scenes", "val_every",
               "save_every", "seed", "safety_quantile", "default_threshold", "max_samples", "per_scene", "out", "data"]
_cfg_values = st.one_of(hostile_counts, json_values, st.lists(st.text(max_size=6), max_size=3).map(tuple),
                        st.sampled_from([(), ("seen", "seen"), ("normal.x",), ("jnyang",), ("psnr", "flip")]))
cfg_cases = st.tuples(
    st.fixed_dictionaries({"metric": st.sampled_from(["jnyang", "psnr", "flip"])},
                          optional=_CFG_VALID),
    st.lists(st.tuples(st.sampled_from(_CFG_FIELDS), _cfg_values), max_size=2),
    st.sampled_from(["missing", "empty"]),
)


def _train_call(v: tuple[dict[str, Any], list[tuple[str, Any]], str]) -> Any:
    kw, hostile, data = v
    d = _fresh("t")
    if data == "empty":
        (d / "data").mkdir()
    out = d / "out" / "m.pt"
    cfg = T.TrainConfig(**{"data": str(d / "data"), "out": str(out), **kw, **dict(hostile)})
    result = T.train(cfg)
    assert not out.exists() or result is not None
    return result


def _always(_value: Any, _result: Any) -> bool:
    return True  # train may never return on a folder that holds no data


# -- rtp.train: recipes ------------------------------------------------------------------------

_RECIPE_KEYS = ["steps", "lr", "arch", "width", "inputs", "val_split", "per_metric", "metrics", "nope", "data", 1, None]
recipe_docs = st.one_of(
    st.dictionaries(st.sampled_from(_RECIPE_KEYS), st.one_of(json_values, hostile_numbers), max_size=3),
    st.builds(lambda m, v: {"per_metric": {m: v}}, st.sampled_from(["jnyang", "psnr"]), json_values),
    json_values,
)
recipe_texts = st.one_of(
    recipe_docs.map(lambda d: yaml.safe_dump(d, allow_unicode=True) if _dumpable(d) else "{"),
    st.text(max_size=30), st.sampled_from(["- a\n- b", "steps: [1", "a: &x 1\nb: *x", "!!python/object:os.system x",
                                            "steps: .nan", "lr: .inf", "\xff", "per_metric: [1]", "1: 2\na: 3"]),
)


def _dumpable(d: Any) -> bool:
    try:
        yaml.safe_dump(d)
    except Exception:  # noqa: BLE001 - NaN keys and the like: skip the case
        return False
    return True


recipe_cases = st.tuples(st.one_of(recipe_texts, st.sampled_from(["@shipped", "@paper-net", "@reuse"]), path_kinds),
                         st.one_of(st.sampled_from(["jnyang", "psnr", "flip"]), json_scalars,
                                   st.lists(st.text(max_size=3), max_size=2)))


def _recipe_source(text: Any) -> Any:
    if isinstance(text, str) and text.startswith("@"):
        return text[1:]
    if isinstance(text, str) and text not in _PATH_KINDS:
        p = _fresh("r") / "recipe.yaml"
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        return p
    return _path(text)


def _recipe_call(v: tuple[Any, Any]) -> Any:
    return T.load_recipe(_recipe_source(v[0]), v[1])


from_recipe_cases = st.tuples(recipe_cases, st.dictionaries(st.sampled_from(_CFG_FIELDS + ["recipe", "nope"]),
                                                            _cfg_values, max_size=2),
                              st.one_of(st.none(), path_kinds))


def _from_recipe_call(v: tuple[tuple[Any, Any], dict[str, Any], Any]) -> Any:
    (text, metric), overrides, scenes = v
    d = _fresh("fr")
    overrides = {k: x for k, x in overrides.items() if k not in ("data", "out", "metric", "recipe", "scenes")}
    return T.TrainConfig.from_recipe(_recipe_source(text), data=str(d), metric=metric, out=str(d / "m.pt"),
                                     scenes=_path(scenes), **overrides)


# -- rtp.train: calibrate_safety ---------------------------------------------------------------

safety_cases = st.tuples(arrays, st.one_of(arrays, st.just("same")),
                         st.one_of(st.just(1.0), st.just(-1.0), hostile_numbers),
                         st.one_of(st.none(), st.floats(0, 0.99), hostile_numbers))


def _safety_call(v: tuple[Any, Any, Any, Any]) -> Any:
    pred = _array(v[0])
    gt = pred if v[1] == "same" else _array(v[1])
    return T.calibrate_safety(pred, gt, worse=v[2], quantile=v[3])


def _safety_absurd(_v: Any, result: Any) -> bool:
    s, share = result
    return not (np.isfinite(s) and s >= 0 and 0 <= share <= 1)


# -- rtp.train.checkpoint.load -----------------------------------------------------------------

def _tiny_net() -> Any:
    return build_network("paper", 4, 4, 16, width=2)


_CK = _WORK / "good.pt"
C.save(_CK, _tiny_net(), _META)
_CK_RAW = torch.load(_CK, map_location="cpu", weights_only=True)
_CK_KEYS = ["format", "format_version", "architecture", "state_dict", "metadata", "training", "versions"]
_tensor = st.sampled_from([torch.zeros(()), torch.zeros(2, 2), torch.full((3,), float("nan")), torch.ones(1, dtype=torch.int8)])
_ck_values = st.one_of(json_values, hostile_numbers, _tensor, st.dictionaries(st.text(max_size=4), _tensor, max_size=2))
checkpoint_cases = st.one_of(
    st.tuples(st.just("field"), st.sampled_from(_CK_KEYS), _ck_values),
    st.tuples(st.just("arch"), st.sampled_from(["name", "config", "in_channels", "out_channels", "tile", "width",
                                                 "head", "nope"]), _ck_values),
    st.tuples(st.just("meta"), st.sampled_from(list(_META) + ["input_multiple", "finite_probe", "schema_version"]),
              st.one_of(json_values, hostile_numbers)),
    st.tuples(st.just("weight"), st.integers(0, 50), _tensor),
    st.tuples(st.just("bytes"), st.integers(0, 2000), st.binary(max_size=8)),
    st.tuples(st.just("whole"), st.just(""), _ck_values),
    st.tuples(st.just("path"), st.just(""), path_kinds),
)


def _checkpoint_file(v: tuple[str, Any, Any]) -> Any:
    kind, key, value = v
    if kind == "path":
        return _path(value)
    p = _fresh("ck") / "model.pt"
    if kind == "bytes":
        data = bytearray(_CK.read_bytes())
        data[key % len(data): key % len(data) + len(value)] = value
        p.write_bytes(bytes(data))
        return p
    raw = {k: (dict(v) if isinstance(v, dict) else v) for k, v in _CK_RAW.items()}
    raw["architecture"] = {**_CK_RAW["architecture"], "config": dict(_CK_RAW["architecture"]["config"])}
    if kind == "field":
        raw[key] = value
    elif kind == "arch":
        (raw["architecture"] if key in ("name",) else raw["architecture"]["config"])[key] = value
    elif kind == "meta":
        raw["metadata"] = {**raw["metadata"], key: value}
    elif kind == "weight":
        sd = dict(raw["state_dict"])
        sd[sorted(sd)[key % len(sd)]] = value
        raw["state_dict"] = sd
    else:
        raw = value
    try:
        torch.save(raw, p)
    except Exception:  # noqa: BLE001 - a value torch cannot save: the file as junk
        p.write_bytes(b"junk")
    return p


def _checkpoint_call(v: tuple[str, Any, Any]) -> Any:
    return C.load(_checkpoint_file(v))


# -- rtp.train.model.build_network -------------------------------------------------------------

_NET_VALID: dict[str, st.SearchStrategy[Any]] = {
    "width": st.sampled_from([2, 4]), "depth": st.integers(0, 3), "stem": st.sampled_from([1, 2, 4]),
    "head": st.sampled_from(["paper", "linear"]), "grow": st.sampled_from([1, 2]), "head_width": st.sampled_from([0, 2]),
}
_NET_HOSTILE = ["width", "head", "depth", "stem", "grow", "stem_layers", "energy_norm", "max_width", "separable",
                "head_width", "context_pool", "block_contrast", "contrast_cell", "separable_tail", "tail_width",
                "contrast_max", "contrast_stored", "contrast_tiles", "coarse", "coarse_width"]
_net_values = st.one_of(hostile_counts, st.integers(-3, 9), json_scalars,
                        st.lists(st.integers(-2, 6), max_size=3).map(tuple))
network_cases = st.tuples(
    st.one_of(st.sampled_from(["paper", "fast"]), json_scalars),
    st.one_of(st.integers(1, 6), hostile_counts), st.one_of(st.integers(1, 6), hostile_counts),
    st.one_of(st.sampled_from([4, 8, 16]), hostile_counts),
    st.fixed_dictionaries({}, optional=_NET_VALID),
    st.lists(st.tuples(st.sampled_from(_NET_HOSTILE), _net_values), max_size=2),
)


def _network_call(v: tuple[Any, Any, Any, Any, dict[str, Any], list[tuple[str, Any]]]) -> Any:
    arch, cin, cout, tile, kw, hostile = v
    net = build_network(arch, cin, cout, tile, **{**kw, **dict(hostile)})
    with torch.no_grad():  # a network that builds must run a frame of its tile
        t = int(tile)
        net.eval()(torch.rand(1, int(cin), 4 * t, 4 * t))
    return net


# -- rtp.export --------------------------------------------------------------------------------

_MODEL = Path(sdk.load("jnyang").path or "")
_MODEL_META = sdk.load(_MODEL).metadata.to_dict()
_OPTION = st.one_of(st.booleans(), json_scalars, st.sampled_from([0, 1, "yes", np.bool_(True)]))
meta_mappings = st.one_of(
    st.builds(lambda k, v: {**_META, k: v}, st.sampled_from(list(_META) + ["provenance", "rate_factors", "description",
                                                                           "input_multiple", "finite_probe", 3]),
              st.one_of(json_values, hostile_numbers)),
    st.dictionaries(st.one_of(st.text(max_size=6), st.integers(), st.none()), json_values, max_size=3),
    json_values, path_kinds, st.just(("a", "b")), st.just([("metric", "jnyang")]),
)


def _meta_arg(m: Any) -> Any:
    return _path(m) if isinstance(m, str) and m in _PATH_KINDS else m


export_cases = st.one_of(
    st.fixed_dictionaries({"checkpoint": st.one_of(st.just("good"), path_kinds)},
                          optional={"output": st.one_of(st.just("same"), st.just("file"), path_kinds),
                                    "opset": st.one_of(st.integers(8, 21), hostile_numbers),
                                    "finite_probe": _OPTION, "split_planes": _OPTION}),
    st.fixed_dictionaries({"checkpoint": st.just("good"), "extra_metadata": meta_mappings}),
    st.builds(lambda c: {"checkpoint": ("bad", c)}, checkpoint_cases),
)


def _export_call(kw: dict[str, Any]) -> Any:
    kw = dict(kw)
    d = _fresh("x")
    ck = kw.pop("checkpoint")
    if ck == "good":
        src = d / "m.pt"
        shutil.copy(_CK, src)
    elif isinstance(ck, tuple):
        src = _checkpoint_file(ck[1])
    else:
        src = _path(ck)
    if "output" in kw:
        kw["output"] = {"same": src, "file": d / "o" / "m.onnx"}.get(kw["output"], None) \
            if kw["output"] in ("same", "file") else _path(kw["output"])
    if "extra_metadata" in kw:
        kw["extra_metadata"] = _meta_arg(kw["extra_metadata"])
    return X.export_checkpoint(src, **kw)


adopt_cases = st.fixed_dictionaries(
    {"foreign": st.one_of(st.just("rtp"), path_kinds), "metadata": st.one_of(st.none(), meta_mappings)},
    optional={"output": st.one_of(st.just("same"), path_kinds), "dynamic": _OPTION, "replace": _OPTION})


def _adopt_call(kw: dict[str, Any]) -> Any:
    d = _fresh("a")
    src = shutil.copy(_MODEL, d / "m.onnx") if kw["foreign"] == "rtp" else _path(kw["foreign"])
    out = kw.get("output", None)
    out = src if out == "same" else (d / "o.onnx" if out is None else _path(out))
    opts = {k: kw[k] for k in ("dynamic", "replace") if k in kw}
    return X.adopt(src, _meta_arg(kw["metadata"]), out, **opts)


_RETUNE = {"default_threshold": st.one_of(st.floats(0, 1), hostile_numbers, json_values),
           "rate_factors": st.one_of(st.none(), json_values, st.dictionaries(st.sampled_from(["1x2", "2x4", "9x9", ""]),
                                                                             hostile_numbers, max_size=2)),
           "description": st.one_of(json_values, hostile_numbers)}
model_path_cases = st.tuples(
    st.sampled_from(["restamp", "retune", "strip_finite_probe", "join_input_planes", "identify"]),
    st.one_of(st.just("copy"), st.just("name"), path_kinds),
    st.one_of(st.just("tmp"), st.just("same"), path_kinds),
    st.one_of(st.fixed_dictionaries({}, optional=_RETUNE), meta_mappings),
)


def _model_path_call(v: tuple[str, Any, Any, Any]) -> Any:
    fn, model, output, meta = v
    d = _fresh("m")
    src = shutil.copy(_MODEL, d / "m.onnx") if model == "copy" else ("jnyang" if model == "name" else _path(model))
    out = d / "o.onnx" if output == "tmp" else (src if output == "same" else _path(output))
    if fn == "restamp":
        return X.restamp(src)
    if fn == "identify":
        return X.identify(src)
    if fn == "retune":
        return X.retune(src, _meta_arg(meta), out)
    return getattr(X, fn)(src, out)


def _onnx_model() -> Any:
    import onnx

    return onnx.load(str(_MODEL))


graph_cases = st.tuples(
    st.sampled_from(["add_finite_probe", "split_input_planes", "merge_slices", "write_metadata"]),
    st.one_of(st.just("model"), st.just("empty"), json_scalars, st.just(b"\x08\x01")),
    st.one_of(st.sampled_from([1, 4, 7]), hostile_counts, st.just("meta"), json_values),
)


def _graph_call(v: tuple[str, Any, Any]) -> Any:
    import onnx

    fn, model, arg = v
    m = _onnx_model() if model == "model" else (onnx.ModelProto() if model == "empty" else model)
    if fn == "merge_slices":
        return X.merge_slices(m)
    if fn == "write_metadata":
        return X.write_metadata(m, sdk.ModelMetadata.from_dict(_MODEL_META) if arg == "meta" else arg)
    return getattr(X, fn)(m, arg)


CASES: list[tuple[Target, int]] = [
    (Target("train: TrainConfig fields refused before any step", cfg_cases, _train_call, _always), 40),
    (Target("train: load_recipe", recipe_cases, _recipe_call), 40),
    (Target("train: TrainConfig.from_recipe", from_recipe_cases, _from_recipe_call), 30),
    (Target("train: calibrate_safety", safety_cases, _safety_call, _safety_absurd), 40),
    (Target("train: checkpoint.load on a fuzzed file", checkpoint_cases, _checkpoint_call), 40),
    (Target("train: model.build_network", network_cases, _network_call), 40),
    (Target("export: export_checkpoint", export_cases, _export_call), 20),
    (Target("export: adopt", adopt_cases, _adopt_call), 25),
    (Target("export: restamp, retune, strip, join, identify", model_path_cases, _model_path_call), 25),
    (Target("export: graph functions on ModelProtos", graph_cases, _graph_call), 20),
]


@pytest.mark.parametrize(("target", "examples"), CASES, ids=[t.name for t, _ in CASES])
def test_malformed_inputs_to_train_and_export_are_typed_errors(target: Target, examples: int) -> None:
    fuzz_bounded(target, examples, refused=("untyped", "hang", "absurd accepted"))
