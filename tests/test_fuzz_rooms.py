"""Property-based fuzzing of the rooms around the SDK (hypothesis): rtp.metrics, rtp.evaluate, rtp.scene
and rtp.capture. Whatever malformed image, map, parameter, frame, scene field, camera, targets file,
dataset file or viewpoint argument arrives, a public function either returns or refuses it with an
rtp.sdk.RtpError (docs/errors.md); no bare numpy, torch, json, pickle or pathlib exception escapes, no
call hangs and none runs out of memory.

The strategies and building blocks are tests/fuzzing.py's (tests/test_fuzz.py fuzzes rtp.sdk and the
dataset reader with them). Sizes are kept tiny and the values that size an allocation or a loop (ray
grids, ray ranges, voxels, attempt counts) are drawn either small or so absurd that numpy refuses them
at once: shrinking a failing example never walks through a value that would really fill the machine.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import zipfile
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import strategies as st

from rtp import evaluate as E
from rtp import metrics as M
from rtp import scene as S
from rtp import sdk
from rtp.capture import (
    BUFFERS,
    DatasetReader,
    DatasetWriter,
    TargetError,
    TargetStore,
    check_frame_memory,
    check_frame_size,
    check_memory,
    job_bytes,
    pool_targets,
)

from .fuzzing import (
    _FILLS,
    Target,
    _array,
    _arrays,
    _near,
    allowed_values,
    arrays,
    code_arrays,
    fuzz_bounded,
    hostile_numbers,
    json_scalars,
    json_values,
    prediction_arrays,
    scratch_folder,
    small_or_absurd,
)

_WORK = scratch_folder("rtp-fuzz-rooms-")


def _val(x: Any) -> Any:
    """An array spec of tests/fuzzing.py (kind, shape, fill) as its array; anything else as it is."""
    if isinstance(x, tuple) and len(x) == 3 and isinstance(x[0], str) and isinstance(x[1], tuple):
        return _array(x)
    return x


def _mirror(a: Any) -> Any:
    """A second image of ``a``'s layout with other values (``1 - a`` for floats)."""
    if isinstance(a, np.ndarray) and a.dtype.kind == "f":
        return (1 - a).astype(a.dtype)
    return a.copy() if isinstance(a, np.ndarray) else a


def _torch(a: Any) -> Any:
    """A numeric (H, W, C) / (N, H, W, C) array as the torch (C, H, W) / (N, C, H, W) tensor the metrics take."""
    import torch

    if not isinstance(a, np.ndarray) or a.dtype.kind not in "biufc" or a.ndim not in (3, 4):
        return a
    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(a, -1, -3)))


#: hostile_numbers without the mid-sized integers that would really allocate or loop (see the docstring).
hostile_counts = hostile_numbers.filter(small_or_absurd)
numbers = st.one_of(st.floats(-10, 10), hostile_numbers)
tiles = st.one_of(st.integers(-2, 40), hostile_numbers)
ppds = st.one_of(st.floats(1, 1000), st.just("width"), hostile_numbers, st.text(max_size=5))
weber_ls = st.one_of(st.floats(1e-6, 1), hostile_numbers)


def _fields(valid: dict[str, st.SearchStrategy[Any]], hostile: dict[str, st.SearchStrategy[Any]],
            required: tuple[str, ...] = ()) -> st.SearchStrategy[dict[str, Any]]:
    """Keyword arguments: valid values (the optional ones drawn or left out), or those with one of them
    replaced by a hostile value, so that most calls get past the first check and reach the code behind it."""
    base = st.fixed_dictionaries({k: valid[k] for k in required},
                                 optional={k: v for k, v in valid.items() if k not in required})
    one = st.sampled_from(sorted(hostile)).flatmap(lambda k: st.tuples(st.just(k), hostile[k]))
    return st.one_of(base, st.builds(lambda b, kv: {**b, kv[0]: kv[1]}, base, one))


# -- rtp.metrics -------------------------------------------------------------------------------

_SIDE = st.integers(1, 12)
#: Images of nearly the right layout ((H, W, 3) or (N, H, W, 3), any dtype and fill) and anything else.
images = st.one_of(
    _near(st.tuples(_SIDE, _SIDE, st.sampled_from([3, 3, 3, 1, 4]))),
    _near(st.tuples(st.integers(0, 2), _SIDE, _SIDE, st.sampled_from([3, 3, 1]))),
    _arrays(st.integers(0, 5), 5),
)
#: Images a metric takes: float (H, W, 3) or (N, H, W, 3) in [0, 1).
good_images = st.tuples(st.sampled_from(["float32", "float32", "float64", "float16"]),
                        st.one_of(st.tuples(_SIDE, _SIDE, st.just(3)), st.tuples(st.integers(1, 2), _SIDE, _SIDE, st.just(3))),
                        st.sampled_from(["random", "random", "zero"]))
#: (reference, test): the same layout with other values, or two independent images.
image_pairs = st.one_of(images.map(lambda s: (s, "mirror")), st.tuples(images, images))
_METRICS = ["flip", "jnflip", "yang", "jnyang", "psnr"]
metric_names = st.one_of(st.sampled_from([*_METRICS, "lpips"]), st.sampled_from(["PSNR", "flip ", "", "1x1"]), json_scalars,
                         st.lists(st.text(max_size=3), max_size=2))
_METRIC_VALID = {"pair": good_images.map(lambda s: (s, "mirror")), "torch": st.booleans(),
                 "tile": st.sampled_from([1, 2, 4, 16]), "ppd": st.one_of(st.floats(1, 100), st.just("width")),
                 "weber_l": st.floats(1e-3, 1), "quirk": st.booleans()}
_METRIC_HOSTILE = {"pair": image_pairs, "tile": tiles, "ppd": ppds, "weber_l": weber_ls, "quirk": json_scalars}


def _pair(p: tuple[Any, Any], torch: bool) -> tuple[Any, Any]:
    ref = _array(p[0])
    tst = _mirror(ref) if p[1] == "mirror" else _array(p[1])
    return (_torch(ref), _torch(tst)) if torch else (ref, tst)


error_map_cases = st.tuples(
    st.sampled_from(["error_map", "tile_metric"]),
    _fields({**_METRIC_VALID, "metric": st.sampled_from(_METRICS)}, {**_METRIC_HOSTILE, "metric": metric_names},
            required=("metric", "pair")))


def _error_map_call(v: tuple[str, dict[str, Any]]) -> Any:
    fn, kw = v
    ref, tst = _pair(kw["pair"], kw.get("torch", False))
    common = {"ppd": kw.get("ppd", M.DEFAULT_PPD), "weber_l": kw.get("weber_l", M.DEFAULT_WEBER_L),
              "lpips_paper_quirk": kw.get("quirk", False)}
    if fn == "error_map":
        return M.error_map(kw["metric"], ref, tst, **common)
    return M.tile_metric(kw["metric"], ref, tst, kw.get("tile", 16), **common)


_MAPS: dict[str, Callable[..., Any]] = {
    "flip_map": lambda r, t, kw: M.flip_map(r, t, **{k: kw[k] for k in ("ppd",) if k in kw}),
    "jnflip_map": lambda r, t, kw: M.jnflip_map(r, t, **{k: kw[k] for k in ("ppd", "weber_l") if k in kw}),
    "yang_map": lambda r, t, kw: M.yang_map(r, t),
    "jnyang_map": lambda r, t, kw: M.jnyang_map(r, t, **{k: kw[k] for k in ("weber_l",) if k in kw}),
    "squared_error_map": lambda r, t, kw: M.squared_error_map(r, t),
    "psnr_tiles": lambda r, t, kw: M.psnr_tiles(r, t, *[kw[k] for k in ("tile",) if k in kw]),
}
map_cases = st.tuples(st.sampled_from(sorted(_MAPS)), _fields(_METRIC_VALID, _METRIC_HOSTILE, required=("pair",)))


def _map_call(v: tuple[str, dict[str, Any]]) -> Any:
    fn, kw = v
    ref, tst = _pair(kw["pair"], kw.get("torch", False))
    return _MAPS[fn](ref, tst, kw)


_RATE_KEYS = st.sampled_from([*sdk.PREDICTED_RATES, *sdk.PREDICTED_RATES, "1x1", "3x3", "2X2", ""])
tile_target_cases = _fields(
    {"reference": good_images.filter(lambda s: len(s[1]) == 3), "images_by_rate": st.just("all"),
     "metrics": st.lists(st.sampled_from(_METRICS), min_size=1, max_size=5), "tile": st.sampled_from([1, 2, 4, 16]),
     "ppd": st.one_of(st.floats(1, 100), st.just("width")), "weber_l": st.floats(1e-3, 1),
     "missing": st.sampled_from(["error", "nan"]), "flip_backend": st.sampled_from([None, "torch", "flip-evaluator"])},
    {"reference": images,
     "images_by_rate": st.one_of(st.dictionaries(_RATE_KEYS, st.one_of(st.just("mirror"), images, json_scalars), max_size=7),
                                 json_values),
     "metrics": st.one_of(st.lists(metric_names, max_size=3), metric_names), "tile": tiles, "ppd": ppds, "weber_l": weber_ls,
     "missing": json_values, "flip_backend": st.one_of(json_scalars, st.lists(st.integers(), max_size=1))},
    required=("reference", "images_by_rate", "metrics"))


def _tile_targets_call(kw: dict[str, Any]) -> Any:
    kw = dict(kw)
    ref = _array(kw.pop("reference"))
    by_rate, metrics = kw.pop("images_by_rate"), kw.pop("metrics")
    if by_rate == "all":
        by_rate = {r: _mirror(ref) for r in sdk.PREDICTED_RATES}
    elif isinstance(by_rate, dict):
        by_rate = {k: _mirror(ref) if x == "mirror" else _val(x) for k, x in by_rate.items()}
    tile = kw.pop("tile", 16)
    return M.tile_targets(ref, by_rate, metrics, tile, **kw)


#: LPIPS runs torch: images around its minimum size only, and few examples.
_LP = st.integers(M.LPIPS_MIN_SIZE - 1, M.LPIPS_MIN_SIZE + 1)
lpips_cases = st.tuples(
    st.sampled_from(["lpips_map", "error_map", "tile_metric", "tile_targets"]),
    st.one_of(st.tuples(st.just("float32"), st.tuples(_LP, _LP, st.just(3)), st.just("random")),
              _near(st.tuples(_LP, _LP, st.just(3))), _near(st.tuples(st.integers(0, 2), _LP, _LP, st.sampled_from([3, 4])))),
    st.booleans(),
    st.one_of(st.none(), st.none(), st.sampled_from(["", "/nonexistent/alex.ckpt", str(_WORK), "a\0b", "x" * 5000]),
              json_scalars, st.lists(st.text(max_size=2), max_size=1)),
)


def _lpips_call(v: tuple[Any, ...]) -> Any:
    fn, spec, torch, weights = v
    ref, tst = _pair((spec, "mirror"), torch)
    if fn == "lpips_map":
        return M.lpips_map(ref, tst, weights=weights)
    if fn == "error_map":
        return M.error_map("lpips", ref, tst)
    if fn == "tile_metric":
        return M.tile_metric("lpips", ref, tst, 16)
    return M.tile_targets(ref, {r: tst for r in sdk.PREDICTED_RATES}, ["lpips"], 16, lpips_weights=weights)


_MAPS_2D = st.tuples(st.sampled_from(["float32", "float64", "float16", "uint8", "int32", "bool"]),
                     st.one_of(st.tuples(_SIDE, _SIDE), st.tuples(st.integers(1, 3), _SIDE, _SIDE)),
                     st.sampled_from(["random", "zero", "nan", "inf"]))
pool_cases = _fields(
    {"values": _MAPS_2D, "torch": st.booleans(), "tile": st.integers(1, 16), "reduce": st.sampled_from(["max", "mean"])},
    {"values": st.one_of(arrays, _near(st.tuples(_SIDE, _SIDE)), json_values), "tile": tiles, "reduce": json_values},
    required=("values", "tile"))


def _pool_call(kw: dict[str, Any]) -> Any:
    a = _val(kw["values"])
    if kw.get("torch") and isinstance(a, np.ndarray) and a.dtype.kind in "biuf":
        import torch as T

        a = T.from_numpy(np.ascontiguousarray(a))
    return M.pool_tiles(a, kw["tile"], *[kw[k] for k in ("reduce",) if k in kw])


weber_cases = _fields({"reference": good_images, "weber_l": st.floats(1e-3, 1)},
                      {"reference": st.one_of(images, json_values), "weber_l": weber_ls}, required=("reference",))
scalar_cases = st.one_of(
    st.tuples(st.just("resolve_ppd"), ppds, st.one_of(st.integers(-2, 4000), hostile_numbers)),
    st.tuples(st.just("check_weber_l"), weber_ls),
    st.tuples(st.just("ppd_from_width"), st.one_of(st.integers(-2, 4000), hostile_numbers), numbers, numbers),
)


def _scalar_call(v: tuple[Any, ...]) -> Any:
    fn, *args = v
    return getattr(M, fn)(*args)


# -- rtp.evaluate ------------------------------------------------------------------------------

_FSIDE = st.integers(1, 20)


def _frame_specs(hw: tuple[int, int]) -> st.SearchStrategy[Any]:
    h, w = hw
    good = st.tuples(st.just("float32"), st.just((h, w, 3)), st.sampled_from(["random", "zero"]))
    rep = st.one_of(good, good, _near(st.just((h, w, 3))), _near(st.sampled_from([(h, w, 4), (h, w), (h, w, 2)])), arrays)

    def opt(shape: tuple[int, ...]) -> st.SearchStrategy[Any]:
        fine = st.tuples(st.sampled_from(["float32", "float16", "float64"]), st.just(shape), st.sampled_from(["random", "zero"]))
        return st.one_of(st.none(), fine, fine, _near(st.just(shape)), arrays, json_scalars)

    return st.one_of(st.tuples(st.just("array"), rep),
                     st.tuples(st.sampled_from(["mapping", "Frame"]), rep, opt((h, w, 2)), opt((h, w))))


#: Frames the baselines read: arrays, mappings of buffers, Frames, a captured Sample, anything else.
frames = st.one_of(st.tuples(_FSIDE, _FSIDE).flatmap(_frame_specs), st.just(("sample",)),
                   st.tuples(st.just("junk"), json_values))


def _frame(spec: tuple[Any, ...]) -> Any:
    kind = spec[0]
    if kind == "array":
        return _array(spec[1])
    if kind == "sample":
        return _template_reader()["s0"]
    if kind == "junk":
        return spec[1]
    rep, motion, seen = (_val(x) for x in spec[1:])
    if kind == "mapping":
        return {"reprojected": rep, "motion": motion, "seen": seen}
    return E.Frame(rep, motion, seen)


selector_thresholds = st.one_of(st.none(), st.floats(0, 2), hostile_numbers)
_MOST = st.one_of(st.floats(-10, 10), hostile_numbers, json_values)
yang_kwargs = _fields(
    {"tile_size": st.sampled_from([2, 4, 8, 16, 32]), "threshold": st.floats(0.01, 2), "env_luminance": st.floats(0, 1),
     "norm": st.sampled_from(["max", "rms"]), "k": st.floats(1, 4), "motion": st.booleans(), "motion_scale": st.floats(0, 4),
     "motion_reduce": st.sampled_from(["min", "mean", "max"]), "allow_4x4": st.booleans(),
     "unseen": st.sampled_from(["as_is", "full"]), "unseen_fraction": st.floats(0, 0.99)},
    {"tile_size": tiles, "threshold": _MOST, "env_luminance": _MOST, "norm": json_values, "k": _MOST, "motion": json_scalars,
     "motion_scale": _MOST, "motion_reduce": json_values, "allow_4x4": json_scalars, "unseen": json_values,
     "unseen_fraction": _MOST})
ffx_kwargs = _fields(
    {"tile_size": st.sampled_from([8, 16, 32]), "cutoff": st.floats(0, 1), "motion_factor": st.floats(0, 1),
     "additional_rates": st.booleans()},
    {"tile_size": tiles, "cutoff": _MOST, "motion_factor": _MOST, "additional_rates": json_scalars})

yang_cases = st.tuples(yang_kwargs, frames, selector_thresholds, allowed_values)
ffx_cases = st.tuples(ffx_kwargs, frames, selector_thresholds, allowed_values)


def _selector_call(cls: Any) -> Callable[[Any], Any]:
    def call(v: tuple[Any, ...]) -> Any:
        kw, frame_spec, threshold, allowed = v
        sel = cls(**kw)
        frame = _frame(frame_spec)
        sel.predict(frame)
        if isinstance(sel, E.Yang2019):
            sel.half_rate_error(frame)
            sel.tile_motion(frame)
        return sel.shading_rates(frame, threshold, allowed)

    return call


restrict_cases = st.tuples(st.one_of(code_arrays, arrays, json_values), allowed_values,
                           st.one_of(st.none(), prediction_arrays, arrays))
monotone_cases = st.tuples(st.one_of(prediction_arrays, arrays, json_values), st.one_of(st.booleans(), json_scalars))

_OPTION = st.one_of(st.sampled_from(["mean", "max", "min", "fresh", "full", "features", "", "h", "r0.5x"]),
                    st.builds(lambda p, v: p + v, st.sampled_from("hrsvc"),
                              st.one_of(hostile_numbers.map(str), st.text(max_size=4),
                                        st.integers(1, 6000).map(lambda n: "1" * n))))
method_texts = st.one_of(
    st.text(max_size=30),
    st.builds(lambda m, k, opts: f"{m}@{k}" + "".join(":" + o for o in opts),
              st.sampled_from(["jnyang", "yang2019", "split.onnx", "", "a@b"]),
              st.one_of(st.integers(-2, 12).map(str), st.text(max_size=4), st.integers(1, 6000).map(lambda n: "1" * n)),
              st.lists(_OPTION, max_size=3)),
    st.lists(st.one_of(st.sampled_from(list(E.METHOD_KINDS)), st.text(max_size=8), json_scalars), max_size=3),
    json_values,
)
_SHARE = st.one_of(st.floats(0, 1), hostile_numbers)
saved_at_cases = st.tuples(
    st.one_of(st.lists(st.tuples(_SHARE, _SHARE), max_size=5), st.lists(st.tuples(st.floats(0, 1), st.floats(0, 1)), max_size=5),
              st.lists(st.one_of(st.tuples(_SHARE), st.tuples(_SHARE, _SHARE, _SHARE), json_scalars), max_size=3),
              json_values),
    _SHARE,
)

# -- rtp.scene -------------------------------------------------------------------------------------


def _vectors(n: int) -> st.SearchStrategy[Any]:
    return st.one_of(st.tuples(*[numbers] * n), st.lists(numbers, max_size=n + 1), _arrays(st.integers(0, 4), 2),
                     hostile_numbers, json_values)


_COORD = st.floats(-10, 10)
_POS = st.tuples(_COORD, _COORD, _COORD)
camera_cases = _fields(
    {"position": _POS, "yaw": st.floats(-360, 360), "pitch": st.floats(-90, 90), "fov_y": st.floats(1, 179),
     "near": st.floats(0.01, 1), "far": st.floats(1.5, 1000), "aspect": st.floats(0.1, 4), "width": st.integers(1, 64),
     "height": st.integers(1, 64)},
    {"position": _vectors(3), "yaw": numbers, "pitch": numbers, "fov_y": numbers, "near": numbers, "far": numbers,
     "aspect": st.one_of(numbers, json_values), "width": st.one_of(st.integers(-2, 64), hostile_numbers),
     "height": st.one_of(st.integers(-2, 64), hostile_numbers)},
    required=("position",))


def _camera_call(kw: dict[str, Any]) -> Any:
    kw = {k: _val(x) for k, x in kw.items()}
    aspect, width, height = kw.pop("aspect", 1.5), kw.pop("width", 32), kw.pop("height", 18)
    cam = S.Camera(**kw)
    cam.rotation()
    cam.view()
    cam.projection(aspect)
    return cam.view_projection(width, height)


_UNIT = st.one_of(st.floats(0, 1), hostile_numbers)
_RGB = st.tuples(st.floats(0, 1), st.floats(0, 1), st.floats(0, 1))
material_kwargs = _fields(
    {"name": st.text(max_size=5), "base_color": st.tuples(st.floats(0, 1), st.floats(0, 1), st.floats(0, 1), st.floats(0, 1)),
     "texture": st.one_of(st.none(), st.tuples(st.just("uint8"), st.tuples(_SIDE, _SIDE, st.just(4)), st.just("random"))),
     "roughness": st.floats(0, 1), "metallic": st.floats(0, 1), "specular": st.floats(0, 1), "emissive": _RGB,
     "alpha_cutoff": st.one_of(st.none(), st.floats(0, 1))},
    {"name": json_values, "base_color": _vectors(4),
     "texture": st.one_of(_near(st.tuples(st.integers(0, 3), st.integers(0, 3), st.sampled_from([4, 4, 3]))), arrays,
                          json_scalars),
     "roughness": _UNIT, "metallic": _UNIT, "specular": _UNIT, "emissive": _vectors(3), "alpha_cutoff": _UNIT},
    required=("name",))


def _mesh_specs(nm: tuple[int, int]) -> st.SearchStrategy[dict[str, Any]]:
    n, m = nm
    floats = st.sampled_from(["float32", "float32", "float64", "float16"])
    ints = st.sampled_from(["int32", "uint32", "int64", "uint8", "int8", "float32"])
    return _fields(
        {"positions": st.tuples(floats, st.just((n, 3)), st.just("random")),
         "normals": st.tuples(floats, st.just((n, 3)), st.just("random")),
         "uvs": st.tuples(floats, st.just((n, 2)), st.just("random")),
         "indices": st.tuples(st.just("uint32"), st.just((m, 3)), st.just("zero" if n else "random")),
         "material": st.integers(0, 3)},
        {"positions": st.one_of(_near(st.just((n, 3))), arrays, json_values),
         "normals": st.one_of(_near(st.sampled_from([(n, 3), (n + 1, 3)])), arrays),
         "uvs": st.one_of(_near(st.sampled_from([(n, 2), (n, 3)])), arrays),
         "indices": st.one_of(st.tuples(ints, st.just((m, 3)), _FILLS), arrays, json_values),
         "material": st.one_of(st.integers(-1, 3), hostile_numbers)},
        required=("positions", "normals", "uvs", "indices", "material"))


mesh_cases = st.tuples(st.integers(0, 12), st.integers(0, 4)).flatmap(_mesh_specs)
_DIR = st.tuples(st.floats(-1, -0.1), st.floats(-1, 1), st.floats(-1, 1))
light_cases = st.one_of(
    st.tuples(st.just("SunLight"), _fields({"direction": _DIR, "colour": _RGB, "intensity": st.floats(0, 10)},
                                           {"direction": _vectors(3), "colour": _vectors(3), "intensity": numbers})),
    st.tuples(st.just("PointLight"), _fields({"position": _POS, "colour": _RGB, "intensity": st.floats(0, 10),
                                              "radius": st.floats(0.1, 20)},
                                             {"position": _vectors(3), "colour": _vectors(3), "intensity": numbers,
                                              "radius": numbers}, required=("position",))),
    st.tuples(st.just("SpawnPoint"), _fields({"position": _POS, "yaw": st.floats(-360, 360)},
                                             {"position": _vectors(3), "yaw": numbers}, required=("position",))),
)


def _valid_mesh(material: int) -> S.Mesh:
    return S.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.zeros((3, 3), np.float32),
                  np.zeros((3, 2), np.float32), np.array([[0, 1, 2]], np.uint32), material)


def _items(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.one_of(st.lists(st.one_of(valid, valid, json_scalars), max_size=3), json_values,
                     st.lists(valid, max_size=2).map(tuple))


_MESHES = st.lists(st.integers(0, 1).map(_valid_mesh), max_size=3)
_MATERIALS = st.lists(st.just(S.Material("m")), min_size=2, max_size=3)
scene_cases = _fields(
    {"name": st.text(max_size=5), "meshes": _MESHES, "materials": _MATERIALS, "sun": st.just(S.SunLight()),
     "point_lights": st.lists(st.just(S.PointLight((0.0, 1.0, 0.0))), max_size=2), "sky_colour": _RGB,
     "ambient": st.floats(0, 1), "spawn_points": st.lists(st.just(S.SpawnPoint((0.0, 1.0, 0.0))), max_size=2)},
    {"name": json_values, "meshes": _items(st.integers(0, 3).map(_valid_mesh)), "materials": _items(st.just(S.Material("m"))),
     "sun": json_scalars, "point_lights": _items(st.just(S.PointLight((0.0, 1.0, 0.0)))), "sky_colour": _vectors(3),
     "ambient": numbers, "spawn_points": _items(st.just(S.SpawnPoint((0.0, 1.0, 0.0))))},
    required=("name", "meshes", "materials"))


def _scene_call(kw: dict[str, Any]) -> Any:
    scene = S.Scene(**{k: _val(x) for k, x in kw.items()})
    return scene.bounds, scene.triangle_count


# -- rtp.capture: a dataset with targets, then corrupted -------------------------------------------

_H, _W = 24, 40
_TEMPLATE = _WORK / "template"


def _buffers() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    out = {}
    for name, spec in BUFFERS.items():
        n = len(spec.channels) or 3
        out[name] = rng.random((_H, _W, n) if n > 1 else (_H, _W), dtype=np.float32)
    return out


@cache
def _template() -> dict[str, bytes]:
    """A one-sample dataset with yang and psnr targets (tests/test_dataset.py's way); the bytes of its files."""
    w = DatasetWriter(_TEMPLATE, settings={"size": [_W, _H]})
    w.write("s0", _buffers(), {"scene": "a", "profile": "slow"})
    w.finalize()
    store = TargetStore(_TEMPLATE)
    rng = np.random.default_rng(1)
    for m in ("yang", "psnr"):
        store.declare(m, {})
        store.write("s0", m, rng.random((6, *sdk.tile_grid(_H, _W, store.base_tile))).astype(np.float32), (_H, _W))
    return {str(p.relative_to(_TEMPLATE)): p.read_bytes() for p in sorted(_TEMPLATE.rglob("*")) if p.is_file()}


def _template_reader() -> DatasetReader:
    _template()
    return DatasetReader(_TEMPLATE)


def _fresh(name: str, replace: dict[str, bytes | None] | None = None) -> Path:
    """A copy of the template in a folder of this process, files in ``replace`` swapped (None: removed).
    Written in the template's order, so targets stay newer than their sample."""
    root = _WORK / f"{name}{os.getpid()}"
    shutil.rmtree(root, ignore_errors=True)
    for rel, original in _template().items():
        data = (replace or {}).get(rel, original)
        if data is None:
            continue
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return root


def _flip(data: bytes, pos: int, bit: int) -> bytes:
    b = bytearray(data)
    b[pos % len(b)] ^= 1 << bit
    return bytes(b)


def _manifests(valid: dict[str, Any]) -> st.SearchStrategy[bytes]:
    """Bytes for a manifest.json: the valid one with a field replaced, bit flips, deep nesting, junk."""
    text = json.dumps(valid)
    return st.one_of(
        st.builds(lambda k, v: json.dumps({**valid, k: v}, default=str, skipkeys=True).encode(),
                  st.sampled_from([*valid, "extra"]), st.one_of(json_values, hostile_numbers)),
        st.builds(lambda k: json.dumps({x: y for x, y in valid.items() if x != k}).encode(), st.sampled_from(list(valid))),
        st.builds(lambda p, b: _flip(text.encode(), p, b), st.integers(0, 10_000), st.integers(0, 7)),
        st.builds(lambda n: ("[" * n + "]" * n).encode(), st.integers(1, 100_000)),
        st.builds(lambda n: ('{"a": ' * n + "1" + "}" * n).encode(), st.integers(1, 100_000)),
        st.builds(lambda n: text.replace("1", "1" + "0" * n, 1).encode(), st.integers(300, 5000)),
        st.binary(max_size=64),
        st.text(max_size=64).map(lambda t: t.encode("utf-8", "surrogatepass")),
        st.sampled_from([b"", b"null", b"NaN", b"\xff\xfe{}", text.replace("{", "{\"format\": NaN, ", 1).encode()]),
        json_values.map(lambda v: json.dumps(v, default=str, skipkeys=True).encode()),
    )


_TARGETS_MANIFEST = {"format": "rtp-targets", "format_version": 1, "base_tile": 4, "metrics": {"psnr": {}, "yang": {}}}
_DATASET_MANIFEST = {"format": "rtp-dataset", "format_version": 1, "settings": {"size": [_W, _H]}, "samples": ["s0"],
                     "bytes_per_sample": 1000}
_METRIC_TILE = st.tuples(st.sampled_from(["yang", "psnr"]), st.sampled_from([4, 8, 12, 16, 32, 64]))


def _load_targets(root: Path, metric: str, tile: int) -> Any:
    store = TargetStore(root)
    store.has("s0", metric)
    return store.load("s0", metric, tile)


def _targets_manifest_call(v: tuple[bytes, tuple[str, int]]) -> Any:
    data, (metric, tile) = v
    return _load_targets(_fresh("tm", {"targets/manifest.json": data}), metric, tile)


def _mutate(data: bytes, mutation: tuple[str, int, int, bytes]) -> bytes:
    kind, pos, bit, junk = mutation
    b = bytearray(data)
    pos %= len(b)
    if kind == "flip":
        b[pos] ^= 1 << bit
    elif kind == "truncate":
        del b[pos:]
    elif kind == "overwrite":
        b[pos:pos + len(junk)] = junk
    else:
        b[pos:pos] = junk
    return bytes(b)


byte_mutations = st.tuples(st.sampled_from(["flip", "flip", "truncate", "overwrite", "insert"]), st.integers(0, 2**31),
                           st.integers(0, 7), st.binary(min_size=1, max_size=16))
#: A targets .npz: its bytes mutated, or members replaced by arrays of any kind, or by junk bytes.
target_file_cases = st.tuples(
    _METRIC_TILE,
    st.one_of(byte_mutations,
              st.fixed_dictionaries({}, optional={
                  "values": st.one_of(_near(st.tuples(st.sampled_from([6, 6, 5]), st.sampled_from([6, 6, 5, 1]),
                                                      st.sampled_from([10, 10, 11, 0]))), arrays),
                  "size": st.one_of(st.tuples(st.sampled_from(["int64", "int64", "float64", "uint8", "int8"]),
                                              st.sampled_from([(2,), (3,), (2, 1), ()]),
                                              st.sampled_from(["random", "zero", "negative", "nan"])), arrays),
                  "junk": st.binary(max_size=32)})),
)


def _target_file_call(v: tuple[tuple[str, int], Any]) -> Any:
    (metric, tile), change = v
    rel = f"targets/{metric}/s0.npz"
    original = _template()[rel]
    if isinstance(change, tuple):
        data = _mutate(original, change)
    else:
        buf = io.BytesIO()
        if "junk" in change:
            with zipfile.ZipFile(buf, "w") as z:
                z.writestr("values.npy", change["junk"])
                z.writestr("size.npy", change["junk"])
        else:
            with np.load(io.BytesIO(original)) as z:
                members = {k: z[k] for k in z.files}
            for k in ("values", "size"):
                if k in change:
                    members[k] = np.asarray(_array(change[k]), dtype=object) if change[k][0] == "ragged" else \
                        np.asarray(_array(change[k]))
            np.savez(buf, **members)
        data = buf.getvalue()
    return _load_targets(_fresh("tf", {rel: data}), metric, tile)


_IDS = st.one_of(st.sampled_from(["s0", "s1", "../s0", "", "s 0", "a" * 300, "s0.npz", "."]), st.text(max_size=6),
                 json_scalars, st.lists(st.text(max_size=2), max_size=1))
_TV = (6, *sdk.tile_grid(_H, _W, 4))
store_cases = st.tuples(
    st.sampled_from(["load", "path", "has", "stale", "declare", "write"]),
    _fields(
        {"root": st.just("template"), "base_tile": st.just(4), "sample_id": st.just("s0"),
         "metric": st.sampled_from(["yang", "psnr"]), "tile": st.sampled_from([4, 8, 16, 32]),
         "params": st.dictionaries(st.sampled_from(["ppd", "weber_l"]), st.floats(0.01, 100), max_size=2),
         "values": st.just(("float32", _TV, "random")), "size": st.just((_H, _W))},
        # (relative roots land in a scratch folder (_store_call); no drawn text: "/x" would write at the root)
        {"root": st.one_of(st.just("empty"), st.sampled_from(["", ".", "sub/dir", "a\0b", "/dev/null", b"x"]),
                           json_scalars.filter(lambda v: not isinstance(v, str))),
         "base_tile": st.one_of(st.none(), tiles), "sample_id": _IDS,
         "metric": st.one_of(st.sampled_from(list(sdk.METRICS)), st.sampled_from(["../samples", "YANG", ""]), json_scalars,
                             st.lists(st.text(max_size=2), max_size=1)),
         "tile": tiles,
         "params": st.one_of(st.dictionaries(st.text(max_size=3), json_values, max_size=3), json_values,
                             st.just({"a": object()}), st.just({1: 2}), st.just({"a": float("nan")})),
         "values": st.one_of(_near(st.just(_TV)), _near(st.tuples(st.sampled_from([6, 5]), st.sampled_from([6, 5]),
                                                                  st.sampled_from([10, 9]))), arrays, json_values),
         "size": st.one_of(st.tuples(st.integers(-1, 48), st.integers(-1, 48)), st.tuples(numbers, numbers), json_values)}),
)


def _store_call(v: tuple[str, dict[str, Any]]) -> Any:
    method, kw = v
    root, base_tile, sample_id = kw.get("root", "template"), kw.get("base_tile"), kw.get("sample_id", "s0")
    metric, tile, params = kw.get("metric", "yang"), kw.get("tile", 4), kw.get("params", {})
    values, size = kw.get("values", ("float32", _TV, "random")), kw.get("size", (_H, _W))
    if root == "template":  # (reads only; a copy where it may write)
        root = _fresh("ts") if method in ("declare", "write") else _template_reader().root
    scratch = _WORK / f"empty{os.getpid()}"
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir()
    if root == "empty":
        root = scratch
    with contextlib.chdir(scratch):  # a relative root writes there, not into the checkout
        return _store_method(TargetStore(root) if base_tile is None else TargetStore(root, base_tile=base_tile),
                             method, sample_id, metric, tile, params, values, size)


def _store_method(store: TargetStore, method: str, sample_id: Any, metric: Any, tile: Any, params: Any, values: Any,
                  size: Any) -> Any:
    if method == "load":
        return store.load(sample_id, metric, tile)
    if method == "path":
        return store.path(sample_id, metric)
    if method == "has":
        return store.has(sample_id, metric)
    if method == "stale":
        return store.stale(sample_id, metric)
    if method == "declare":
        return store.declare(metric, params)
    return store.write(sample_id, metric, _val(values), size)


def _pool_target_specs(hwb: tuple[int, int, int]) -> st.SearchStrategy[dict[str, Any]]:
    h, w, base = hwb
    grid = (6, -(-h // base), -(-w // base))
    return _fields(
        {"values": st.tuples(st.sampled_from(["float32", "float64", "float16"]), st.just(grid),
                             st.sampled_from(["random", "zero", "nan", "inf"])),
         "size": st.just((h, w)), "base": st.just(base), "tile": st.integers(1, 6).map(lambda k: k * base),
         "mse": st.booleans()},
        {"values": st.one_of(_near(st.tuples(st.sampled_from([6, 6, 1]), st.integers(0, 8), st.integers(0, 8))), arrays,
                             json_values),
         "size": st.one_of(st.tuples(st.integers(-1, 40), st.integers(-1, 40)), st.tuples(numbers, numbers), json_values),
         "base": tiles, "tile": tiles, "mse": json_scalars},
        required=("values", "size", "base", "tile", "mse"))


pool_target_cases = st.tuples(st.integers(1, 40), st.integers(1, 40), st.sampled_from([1, 2, 4, 8])).flatmap(_pool_target_specs)

def _pool_targets_call(kw: dict[str, Any]) -> Any:
    return pool_targets(_val(kw["values"]), kw["size"], kw["base"], kw["tile"], mse=kw["mse"])


def _read_everything(root: Path) -> Any:
    reader = DatasetReader(root)
    out = []
    for s in reader:
        out.append((dict(s.meta), s.size, s.inputs(list(sdk.CHANNELS)), [s.final(r) for r in sdk.ALL_RATES]))
    reader.select(scene="a")
    return out


dataset_manifest_cases = _manifests(_DATASET_MANIFEST)
sample_file_cases = st.one_of(byte_mutations, st.tuples(st.just("member"), st.sampled_from(["meta", "depth", "final_1x1", "*"]),
                                                        st.binary(max_size=32)))


def _sample_file_call(change: tuple[Any, ...]) -> Any:
    rel = "samples/s0.npz"
    original = _template()[rel]
    if change[0] == "member":  # a well-formed archive whose members are junk
        _, which, junk = change
        buf = io.BytesIO()
        with np.load(io.BytesIO(original)) as z, zipfile.ZipFile(buf, "w") as out:
            for name in z.files:
                if which in (name, "*"):
                    out.writestr(f"{name}.npy", junk)
        data = buf.getvalue()
    else:
        data = _mutate(original, change)
    return _read_everything(_fresh("sf", {rel: data}))


lookup_cases = st.tuples(st.sampled_from(["reader", "buffer", "channel", "inputs", "final", "select"]),
                         st.one_of(_IDS, st.sampled_from([*BUFFERS, *sdk.CHANNELS, *sdk.ALL_RATES]), json_values))


def _lookup_call(v: tuple[str, Any]) -> Any:
    method, name = v
    reader = _template_reader()
    if method == "reader":
        return reader[name]
    if method == "select":
        return reader.select(**({name: name} if isinstance(name, str) else {"scene": name}))
    return getattr(reader["s0"], method)(name)


frame_size_cases = st.tuples(
    st.one_of(st.tuples(st.integers(-2, 40), st.integers(-2, 40)), st.lists(st.one_of(st.integers(0, 2**20), hostile_numbers),
                                                                              max_size=3),
              st.tuples(hostile_numbers, hostile_numbers), arrays, json_values,
              st.builds(lambda a, b: (np.int64(a), np.uint8(b)), st.integers(0, 2**20), st.integers(0, 255))),
    st.one_of(st.just("size"), st.text(max_size=5), json_scalars),
)

#: rtp.capture.paths.DynamicResolution: (scales, every, a full size for size(), a text for parse()).
dynamic_cases = st.tuples(
    st.one_of(st.lists(st.one_of(st.floats(0.01, 1.0), st.integers(-1, 2), hostile_numbers), max_size=4).map(tuple),
              json_values, arrays),
    st.one_of(st.integers(-2, 40), hostile_numbers, json_scalars),
    st.tuples(st.integers(16, 4000), st.integers(16, 4000)),
    st.one_of(st.text(alphabet="0123456789.,@-enaix ", max_size=12), json_scalars),
)


def _dynamic_call(v: tuple[Any, ...]) -> Any:
    from rtp.capture.paths import DynamicResolution

    scales, every, full, text = v
    with contextlib.suppress(sdk.RtpError):  # (a refused text is typed; the constructor's call still runs)
        DynamicResolution.parse(text)
    dyn = DynamicResolution(_val(scales), every)
    sizes = [dyn.size(i, full) for i in range(3 * len(dyn.scales) * min(dyn.every, 5))]
    if not all(16 <= w <= full[0] and 16 <= h <= full[1] for w, h in sizes) or not dyn.sizes(full):
        raise AssertionError(f"{dyn}: sizes {sizes} outside 16 .. {full}")  # (accepted and absurd: untyped, a bug)
    return dyn


job_memory_cases = st.tuples(
    st.one_of(st.sampled_from(["capture", "targets", "demo", "play", "metric"]), json_scalars),
    frame_size_cases.map(lambda case: case[0]),
    st.one_of(st.integers(-2, 40), hostile_numbers),  # processes
    st.one_of(st.sampled_from(list(sdk.METRICS)), st.lists(st.one_of(st.sampled_from(list(sdk.METRICS)), json_scalars),
                                                           max_size=3), json_values),
    st.one_of(st.integers(-2, 100), hostile_numbers),  # loops
    st.one_of(st.integers(-2, 10), hostile_numbers),  # models
    st.one_of(st.integers(0, 2**45), hostile_numbers),  # bytes needed
    st.one_of(st.text(max_size=5), json_scalars),  # what is said of them
)


def _job_memory_call(v: tuple[Any, ...]) -> None:
    job, size, processes, metrics, loops, models, need, said = v
    kw = {"processes": processes, "metrics": metrics, "loops": loops, "models": models}
    with contextlib.suppress(sdk.ParameterError):  # (each call on its own: the second runs after the first's refusal)
        job_bytes(job, _val(size), **kw)
    with contextlib.suppress(sdk.ParameterError):
        check_frame_memory(job, _val(size), **kw)
    check_memory(need, said, "size", "of memory: less")


# -- rtp.capture.viewpoints ---------------------------------------------------------------------------


@cache
def _procedural() -> Any:
    from rtp.capture import scenes

    return scenes.procedural(0)


_EXTREMES = st.one_of(st.sampled_from([1e308, 1.7e308, 1e300, 1e15]),
                      st.sampled_from([float("nan"), float("inf"), -float("inf"), -1.0, 0.0, -0.0]),
                      st.sampled_from([10**400, -(10**400), "1", None, True, [1.0]]))
#: Values that size grids, ray ranges or loops: sensible ranges, or extremes numpy refuses at once.
_vp_kwargs = _fields(
    {"n": st.integers(0, 2), "seed": st.integers(0, 2**64), "max_attempts": st.integers(0, 3),
     "profile": st.sampled_from(["slow", "fast", "frame"]), "placement": st.sampled_from(["free", "eye"]),
     "voxel": st.floats(0.25, 1), "clearance": st.floats(0, 0.5), "pitch_limit": st.floats(0, 90),
     "min_coverage": st.one_of(st.floats(0, 1), st.lists(st.floats(0, 1), min_size=1, max_size=3)),
     "max_distance": st.floats(0.1, 200), "rays": st.tuples(st.integers(1, 40), st.integers(1, 24)),
     "aspect": st.floats(0.2, 5), "fov_y": st.floats(1, 179), "max_height": st.one_of(st.none(), st.floats(0.5, 10)),
     "prev_tries": st.integers(1, 20), "stats": st.one_of(st.none(), st.just({})),
     "blockers": st.one_of(st.none(), st.tuples(st.just("float64"), st.tuples(st.integers(0, 3), st.just(3), st.just(3)),
                                                st.just("random")))},
    {"n": st.one_of(st.integers(-2, 2), hostile_counts.filter(lambda v: not isinstance(v, (int, np.integer)) or v < 3)),
     "seed": hostile_numbers,
     # (max_attempts None is 1200 draws: never drawn)
     "max_attempts": st.one_of(st.integers(-(2**70), -1), st.floats(), st.text(max_size=3), st.booleans()),
     "profile": st.one_of(json_scalars, st.lists(st.text(max_size=2), max_size=1),
                          st.builds(lambda n, t, r: ("MotionProfile", n, t, r), st.text(max_size=3),
                                    st.one_of(st.floats(0, 2), _EXTREMES), st.one_of(st.floats(0, 20), _EXTREMES))),
     "placement": json_values,
     "voxel": _EXTREMES,  # (tiny voxels are coarsened to a 24 M voxel grid: 7 s a call)
     "clearance": _EXTREMES, "pitch_limit": _EXTREMES,
     "min_coverage": st.one_of(_EXTREMES, st.lists(st.one_of(st.floats(0, 1), _EXTREMES), max_size=3),
                               st.text(max_size=3), json_values),
     "max_distance": _EXTREMES,
     "rays": st.one_of(st.tuples(hostile_counts, hostile_counts), json_values,
                       st.sampled_from([(10**7, 10**7), (2**40, 1), (0, 18), (32,), (32, 18, 1), "ab"])),
     "aspect": _EXTREMES, "fov_y": _EXTREMES, "max_height": _EXTREMES, "prev_tries": hostile_counts,
     "stats": json_values,
     "blockers": st.one_of(_near(st.tuples(st.integers(0, 3), st.sampled_from([3, 3, 2]), st.just(3))), arrays, json_values)},
    required=("n", "seed", "max_attempts"))
viewpoint_cases = st.tuples(st.sampled_from(["procedural"] * 6 + ["empty", "no spawn", "junk"]), _vp_kwargs)


def _viewpoints_call(v: tuple[str, dict[str, Any]]) -> Any:
    from rtp.capture.viewpoints import MotionProfile, sample_viewpoints

    which, kw = v[0], dict(v[1])
    if isinstance(kw.get("profile"), tuple):
        kw["profile"] = MotionProfile(*kw["profile"][1:])
    if "blockers" in kw:
        kw["blockers"] = _val(kw["blockers"])
    scenes: dict[str, Callable[[], Any]] = {
        "procedural": _procedural, "empty": lambda: S.Scene("empty", [], [], spawn_points=[S.SpawnPoint((0, 1, 0))]),
        "no spawn": lambda: S.Scene("bare", [_valid_mesh(0)], [S.Material("m")]), "junk": lambda: "procedural:0"}
    scene = scenes[which]()
    n, seed = kw.pop("n"), kw.pop("seed")
    return sample_viewpoints(scene, n, seed, **kw)


# -- an engine's frames imported (rtp.capture.import_frames) ---------------------------------------

_IH, _IW = 8, 12


@cache
def _import_template() -> dict[str, np.ndarray]:
    """A frame an engine could dump (12x8, view = identity, OpenGL perspective): valid G-buffers and finals."""
    rng = np.random.default_rng(3)
    n, f, t = 0.1, 100.0, np.tan(np.radians(30))
    proj = np.array([[1 / (t * _IW / _IH), 0, 0, 0], [0, 1 / t, 0, 0], [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)],
                     [0, 0, -1, 0]])
    normal = rng.normal(size=(_IH, _IW, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 1
    frame = {"depth": rng.uniform(1, 5, (_IH, _IW)), "albedo": rng.random((_IH, _IW, 3)),
             "normal": normal / np.linalg.norm(normal, axis=-1, keepdims=True), "roughness": rng.random((_IH, _IW)),
             "view": np.eye(4), "projection": proj, "prev_colour": rng.random((_IH, _IW, 3)),
             "prev_depth": rng.uniform(1, 5, (_IH, _IW)), "prev_view_projection": proj}
    frame.update({f"final_{r}": rng.random((_IH, _IW, 3)) for r in sdk.ALL_RATES})
    return {k: np.asarray(v, np.float64 if v.shape == (4, 4) else np.float32) for k, v in frame.items()}


_IMPORT_KEYS = st.sampled_from([*_import_template(), "shadow", "motion", "prev_projection", "colour", "junk"])
import_cases = st.tuples(
    st.lists(st.tuples(_IMPORT_KEYS, st.one_of(st.none(), _near(st.just((_IH, _IW, 3))), _near(st.just((_IH, _IW))),
                                               _near(st.just((4, 4))), arrays)), max_size=3),
    st.fixed_dictionaries({}, optional={
        "scene": st.one_of(st.sampled_from(["lvl", "a b", "", "x" * 70]), json_scalars),
        "profile": st.one_of(st.sampled_from(["engine", "", "a/b"]), json_scalars),
        "albedo_linear": st.one_of(st.booleans(), json_scalars),
        "normal_space": st.one_of(st.sampled_from([*sdk.NORMAL_SPACES, "clip"]), json_scalars),
        "depth_kind": st.one_of(st.sampled_from([*sdk.DEPTH_KINDS, "log"]), json_scalars),
        "tolerance": hostile_numbers}),
)


def _import_call(v: tuple[list[tuple[str, Any]], dict[str, Any]]) -> Any:
    """A frame with arrays replaced (None: removed), imported with those keywords; what it wrote read back."""
    from rtp.capture import import_frames

    changes, kw = v
    frame = dict(_import_template())
    for key, spec in changes:
        if spec is None:
            frame.pop(key, None)
        else:
            frame[key] = _array(spec)
    folder = _WORK / "import" / "lvl"
    shutil.rmtree(_WORK / "import", ignore_errors=True)
    folder.mkdir(parents=True)
    try:
        np.savez(folder / "frame_0.npz", **frame)
    except (ValueError, TypeError):  # (numpy cannot save it: not a frame an engine could dump)
        return None
    report = import_frames(folder, _WORK / "import" / "data", **kw)
    reader = DatasetReader(_WORK / "import" / "data")
    held = [c for c in sdk.CHANNELS if not any(c in BUFFERS[b].channels for b in reader.absent)]
    return report, [(s.inputs(held), [s.final(r) for r in sdk.ALL_RATES], dict(s.meta)) for s in reader]


# -- the targets -----------------------------------------------------------------------------------

#: (target, examples): budgets sized for about 25 s of the whole file on two cores.
CASES: list[tuple[Target, int]] = [
    (Target("metrics: error_map, tile_metric", error_map_cases, _error_map_call), 80),
    (Target("metrics: flip/jnflip/yang/jnyang/squared_error maps, psnr_tiles", map_cases, _map_call), 100),
    (Target("metrics: lpips (images around its minimum size)", lpips_cases, _lpips_call), 10),
    (Target("metrics: tile_targets", tile_target_cases, _tile_targets_call), 60),
    (Target("metrics: pool_tiles", pool_cases, _pool_call), 100),
    (Target("metrics: weber_denominator", weber_cases, lambda kw: M.weber_denominator(_val(kw["reference"]),
                                                                                      *[kw[k] for k in ("weber_l",) if k in kw])),
     80),
    (Target("metrics: resolve_ppd, check_weber_l, ppd_from_width", scalar_cases, _scalar_call), 100),
    (Target("evaluate: Yang2019 parameters, predict and shading_rates", yang_cases, _selector_call(E.Yang2019)), 100),
    (Target("evaluate: FidelityFX parameters, predict and shading_rates", ffx_cases, _selector_call(E.FidelityFX)), 100),
    (Target("evaluate: restrict_rates", restrict_cases, lambda v: E.restrict_rates(_val(v[0]), v[1], _val(v[2]))), 100),
    (Target("evaluate: monotone_over_rates", monotone_cases, lambda v: E.monotone_over_rates(_val(v[0]), v[1])), 100),
    (Target("evaluate: parse_methods", method_texts, E.parse_methods), 100),
    (Target("evaluate: saved_at", saved_at_cases, lambda v: E.saved_at(*v)), 100),
    (Target("scene: Camera fields and matrices", camera_cases, _camera_call), 100),
    (Target("scene: Material", material_kwargs, lambda kw: S.Material(**{k: _val(x) for k, x in kw.items()})), 100),
    (Target("scene: Mesh", mesh_cases, lambda kw: S.Mesh(**{k: _val(x) for k, x in kw.items()})), 80),
    (Target("scene: SunLight, PointLight, SpawnPoint", light_cases,
            lambda v: getattr(S, v[0])(**{k: _val(x) for k, x in v[1].items()})), 100),
    (Target("scene: Scene", scene_cases, _scene_call), 100),
    (Target("capture: TargetStore with a fuzzed targets manifest.json", st.tuples(_manifests(_TARGETS_MANIFEST), _METRIC_TILE),
            _targets_manifest_call), 80),
    (Target("capture: TargetStore with a fuzzed targets .npz", target_file_cases, _target_file_call), 80),
    (Target("capture: TargetStore arguments", store_cases, _store_call), 100),
    (Target("capture: pool_targets", pool_target_cases, _pool_targets_call), 100),
    (Target("capture: DatasetReader with a fuzzed manifest.json", dataset_manifest_cases,
            lambda data: _read_everything(_fresh("dm", {"manifest.json": data}))), 60),
    (Target("capture: DatasetReader with a fuzzed sample .npz", sample_file_cases, _sample_file_call), 60),
    (Target("capture: DatasetReader and Sample lookups", lookup_cases, _lookup_call), 80),
    (Target("capture: check_frame_size(renderer=False)", frame_size_cases,
            lambda v: check_frame_size(_val(v[0]), v[1], renderer=False)), 100),
    (Target("capture: DynamicResolution (scales, every, parse, sizes)", dynamic_cases, _dynamic_call), 100),
    (Target("capture: sample_viewpoints on procedural(0)", viewpoint_cases, _viewpoints_call), 80),
    (Target("capture: job_bytes, check_frame_memory, check_memory", job_memory_cases, _job_memory_call), 100),
    (Target("capture: import_frames of a fuzzed engine frame", import_cases, _import_call), 80),
]


@pytest.mark.parametrize(("target", "examples"), CASES, ids=[t.name for t, _ in CASES])
def test_malformed_inputs_to_the_rooms_are_typed_errors(target: Target, examples: int) -> None:
    fuzz_bounded(target, examples, refused=("untyped", "hang"))


@pytest.mark.parametrize("method", ["declare", "write", "load", "has"])
def test_a_target_store_on_a_file_is_a_typed_error(method: str) -> None:
    """A drawn case one run in twenty met: TargetStore("/dev/null").declare(...) was a NotADirectoryError."""
    with pytest.raises(TargetError, match="not a folder"):
        _store_call((method, {"root": "/dev/null"}))
