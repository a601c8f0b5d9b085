"""Training recipes: the hyper-parameters of a model as a YAML file, recorded in its provenance.

A recipe sets :class:`~rtp.train.TrainConfig` fields (everything but ``data``, ``metric`` and
``out``), optionally ``val_split`` (hold out the maps of that split of ``scenes.yaml``),
``per_metric`` overrides and ``metrics`` (the metrics it is for, when not every one). ``shipped``
names the recipe of rtp's shipped models, which ships with the package, so ``rtp train --data D
--metric M --out M.pt`` reproduces a shipped model. The other recipes in ``train/recipes/`` are
found by name too (:func:`packaged_recipes`): ``paper-net`` is the recipe of the paper's network
that rtp shipped before its fast network family, ``reuse`` the recipe of ``jnyang-reuse``, the
JNYang model that splits for prediction reuse.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import numbers
import os
import reprlib
import typing
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rtp.metrics import MetricParameterError, known_metrics, metric_info
from rtp.sdk import ParameterError
from rtp.sdk.files import yaml_problem

__all__ = ["SHIPPED_RECIPE", "Recipe", "RecipeError", "load_recipe", "packaged_recipes"]

#: The name of the recipe rtp's shipped models were trained with.
SHIPPED_RECIPE = "shipped"
_SET_BY_CALLER = ("data", "metric", "out", "val_scenes", "recipe", "device")
#: The fields of :data:`_SET_BY_CALLER` a recipe may not set, but the training (the flag of ``rtp train`` that does).
_CALLER_FLAGS = {"data": "--data", "metric": "--metric", "out": "--out", "val_scenes": "--val-scenes", "recipe": "--config"}


class RecipeError(ParameterError):
    """A recipe file is missing, not YAML, or sets an unknown key or a value of the wrong type."""


@dataclasses.dataclass(frozen=True)
class Recipe:
    """A recipe resolved for one metric: the values it sets, where it came from and its digest."""

    name: str
    sha256: str
    values: dict[str, Any]
    val_split: str | None = None

    def provenance(self) -> dict[str, Any]:
        """What a model's provenance records of its recipe."""
        return {"name": self.name, "sha256": self.sha256, "values": dict(self.values), "val_split": self.val_split}


def packaged_recipes() -> list[str]:
    """Names of the recipes that ship with rtp (``train/recipes/NAME.yaml``), ``shipped`` first."""
    names = sorted(f.name.removesuffix(".yaml") for f in resources.files("rtp.train").joinpath("recipes").iterdir()
                   if f.name.endswith(".yaml"))
    return sorted(names, key=lambda n: n != SHIPPED_RECIPE)


def _recipe_text(source: str | os.PathLike[str]) -> tuple[str, str]:
    if not isinstance(source, (str, os.PathLike)):
        raise RecipeError(f"recipe: expected a YAML path or the name of a packaged recipe ({', '.join(packaged_recipes())}), "
                          f"got {type(source).__name__}", "recipe")
    path = Path(source)
    if not path.is_file() and str(source) in packaged_recipes():
        # (UTF-8 as a user's recipe is read: the locale's encoding failed on the R² of the shipped recipes under an
        # ASCII locale, and under cp1252 or Latin-1 gave other text, so another digest in the model's provenance)
        return str(source), resources.files("rtp.train").joinpath(f"recipes/{source}.yaml").read_text(encoding="utf-8")
    if not path.is_file():
        raise RecipeError(f"recipe {str(source)!r}: no such file (or pass the name of one that ships with rtp: "
                          f"{', '.join(packaged_recipes())}; {SHIPPED_RECIPE!r} is the shipped models' recipe)")
    try:
        return str(path), path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise RecipeError(f"recipe {path}: cannot be read as UTF-8 text ({err})") from err


def _field_types() -> dict[str, Any]:
    from ._loop import TrainConfig

    hints = typing.get_type_hints(TrainConfig)
    return {f.name: hints[f.name] for f in dataclasses.fields(TrainConfig) if f.name not in _SET_BY_CALLER}


def _coerce(name: str, value: Any, kind: Any, what: str = "recipe key") -> Any:
    """``value`` as the field type ``kind`` (bool, int, float, str, tuple[str, ...], or optional of one)."""
    args = typing.get_args(kind)
    if type(None) in args:
        if value is None:
            return None
        kind = next(a for a in args if a is not type(None))
    if typing.get_origin(kind) is tuple:
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise RecipeError(f"{what} {name!r}: expected a list of names, got {value!r}", name)
        return tuple(value)
    if kind is bool and isinstance(value, (bool, np.bool_)):  # (numpy's flags as Python's, as the SDK takes them)
        return bool(value)
    if kind is bool or isinstance(value, bool):  # YAML's true is no number, nor 1 a switch
        raise RecipeError(f"{what} {name!r}: expected {kind.__name__}, got {value!r}", name)
    if kind is int and isinstance(value, numbers.Integral):
        return int(value)
    if kind is float and isinstance(value, (numbers.Integral, numbers.Real)):
        if not _finite(value):  # (the number is of the type: its value is what is wrong)
            raise RecipeError(f"{what} {name!r}: expected a finite number, got {value!r}", name)
        return float(value)
    if kind is float and isinstance(value, str) and what == "recipe key":
        # (YAML 1.1, which PyYAML reads, takes 5e-4 for a string: its floats need a dot, 5.0e-4; a number
        # float() reads is taken as that number)
        try:
            number = float(value)
        except ValueError:
            raise RecipeError(f"{what} {name!r}: expected float, got {reprlib.repr(value)}", name) from None
        if not math.isfinite(number):
            raise RecipeError(f"{what} {name!r}: expected a finite number, got {reprlib.repr(value)}", name)
        return number
    if kind is str and isinstance(value, str):
        return value
    raise RecipeError(f"{what} {name!r}: expected {getattr(kind, '__name__', kind)}, got {reprlib.repr(value)}", name)


def _finite(value: Any) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an int past float's range
        return False


def check_fields(cfg: Any) -> dict[str, Any]:
    """Every field of a ``TrainConfig`` of its annotated type (``train`` calls this before any work: a
    list for the metric, a string for a rate or a float for the outputs failed deep in the checks as a
    TypeError). ``data`` and ``out`` may be paths. Returns the fields as the types they are read as
    (:func:`normal_fields`)."""
    from ._loop import TrainConfig

    return normal_fields({f.name: getattr(cfg, f.name) for f in dataclasses.fields(TrainConfig)})


def normal_fields(values: dict[str, Any]) -> dict[str, Any]:
    """``values`` (TrainConfig fields) each as its field's type: numpy's integers, floats and flags as
    Python's (``seed=np.int64(3)`` reached torch's generator as a TypeError, ``lr=np.float32(1e-3)`` the
    checkpoint's JSON, both once the data was loaded), a list as a tuple and a comma-separated string as
    its names (``val_scenes="scene0"`` was read letter by letter). A value of another type is a
    :class:`RecipeError` naming the field."""
    from ._loop import TrainConfig

    hints = typing.get_type_hints(TrainConfig)
    out: dict[str, Any] = {}
    for name, value in values.items():
        if name in ("data", "out") and isinstance(value, os.PathLike):
            out[name] = value
        elif name == "recipe":
            if value is not None and not isinstance(value, dict):
                raise RecipeError(f"field 'recipe': expected None or the recipe's provenance mapping, got "
                                  f"{type(value).__name__}", "recipe")
            out[name] = value
        else:
            out[name] = _coerce(name, value, hints[name], what="field")
    return out


def load_recipe(source: str | os.PathLike[str], metric: str) -> Recipe:
    """Read a recipe (a YAML path, or the name of a packaged recipe such as :data:`SHIPPED_RECIPE`)
    and resolve it for ``metric``.

    Raises :class:`RecipeError` naming the key at fault for unknown keys and wrong types.
    """
    try:
        metric_info(metric)  # rtp's own or a plugin's
    except MetricParameterError as err:
        raise RecipeError(str(err), "metric") from None
    name, text = _recipe_text(source)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise RecipeError(f"recipe {name}: not valid YAML ({yaml_problem(err)})") from err
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise RecipeError(f"recipe {name}: expected a mapping of TrainConfig fields, got {type(data).__name__}")
    keys = [k for k in data if not isinstance(k, str)]
    if keys:  # ("0:" is a key YAML reads as the number 0)
        raise RecipeError(f"recipe {name}: keys are field names, got {keys[0]!r}")
    data = dict(data)
    per_metric = data.pop("per_metric", None)
    if per_metric is None:  # (``per_metric:`` with nothing under it; ``[]``, ``0`` or ``false`` were taken as none too)
        per_metric = {}
    if not isinstance(per_metric, dict) or not all(isinstance(v, dict) and all(isinstance(k, str) for k in v)
                                                   for v in per_metric.values()):
        raise RecipeError(f"recipe {name}: per_metric must map metric names to mappings of fields, got "
                          f"{reprlib.repr(per_metric)}", "per_metric")
    for section_metric, section in per_metric.items():
        nested = [k for k in ("metrics", "per_metric") if k in section]
        if nested:  # (was "unknown key(s) metrics (metrics: did you mean metrics?)": the key is right, its place is not)
            raise RecipeError(f"recipe {name}: per_metric {section_metric} sets {nested[0]!r}, a key of the recipe's top "
                              f"level, not of a metric's section: move it out of per_metric", nested[0])
    import difflib

    known = known_metrics()
    metrics = data.pop("metrics", None)
    if metrics is not None:  # a recipe measured for some metrics only (``reuse``: JNYang)
        if not isinstance(metrics, list) or not metrics or not all(isinstance(m, str) for m in metrics):
            raise RecipeError(f"recipe key 'metrics': expected a list of metric names, got {metrics!r}", "metrics")
        strange = [m for m in metrics if m not in known]
        if strange:  # ("is for jnyng (measured for those only), got metric 'jnyang'" for a typo)
            close = {m: difflib.get_close_matches(m, known, n=1) for m in strange}
            guess = "".join(f" ({m}: did you mean {c[0]}?)" for m, c in close.items() if c)
            raise RecipeError(f"recipe {name}: metrics names unknown metric(s) {', '.join(strange)}{guess}; expected "
                              f"among {', '.join(known)}", "metrics")
        if metric not in metrics:
            raise RecipeError(f"recipe {name} is for {', '.join(metrics)} (measured for those only), got metric "
                              f"{metric!r}; the shipped recipe, {SHIPPED_RECIPE!r}, trains every metric", "metrics")
    strange = [m for m in per_metric if m not in known]
    if strange:  # (a typo'd metric's section was never read: its values trained nothing, silently)
        close = {m: difflib.get_close_matches(str(m), known, n=1) for m in strange}
        guess = "".join(f" ({m}: did you mean {c[0]}?)" for m, c in close.items() if c)
        raise RecipeError(f"recipe {name}: per_metric names unknown metric(s) {', '.join(map(str, strange))}{guess}; "
                          f"expected among {', '.join(known)}", "per_metric")
    # every metric's section is checked, not only the one trained now (a typo there surfaced only when that
    # metric was trained, the recipe's digest by then in other models' provenance)
    sections = [(m, {**data, **values}) for m, values in per_metric.items() if m != metric]
    resolved = _checked(name, {**data, **per_metric.get(metric, {})})
    for other, section in sections:
        try:
            _checked(name, section)
        except RecipeError as err:
            raise RecipeError(f"per_metric {other}: {err}", err.name) from None
    values, val_split = resolved
    return Recipe(name, hashlib.sha256(text.encode()).hexdigest(), values, val_split)


def _checked(name: str, merged: dict[str, Any]) -> tuple[dict[str, Any], str | None]:
    """The recipe's values for one metric (its keys and its section of ``per_metric`` merged), each of its
    field's type, and its ``val_split``; an unknown key or a wrong type is a :class:`RecipeError`."""
    merged = dict(merged)
    val_split = merged.pop("val_split", None)
    if val_split is not None and not isinstance(val_split, str):
        raise RecipeError(f"recipe key 'val_split': expected a split name, got {val_split!r}", "val_split")
    if "device" in merged:  # (a TrainConfig field, but the machine's: the same recipe trains anywhere)
        raise RecipeError(f"recipe {name}: 'device' is the machine's, not the recipe's: give it to the training "
                          f"(rtp train --device, TrainConfig.device)", "device")
    given = [k for k in merged if k in _CALLER_FLAGS]
    if given:  # (the training's own fields: "unknown key out (did you mean outputs?)", "val_scenes (... val_every?)")
        key = given[0]
        split = {"val_scenes": "; a recipe holds out the maps of a split of scenes.yaml with val_split",
                 "metric": "; a recipe lists the metrics it is for with metrics"}.get(key, "")
        raise RecipeError(f"recipe {name}: {key!r} is the training's, not the recipe's: give it to the training "
                          f"(rtp train {_CALLER_FLAGS[key]}, {'TrainConfig.from_recipe' if key == 'recipe' else 'TrainConfig'}"
                          f"{'' if key == 'recipe' else '.' + key}){split}", key)
    types = _field_types()
    unknown = sorted(set(merged) - set(types))
    if unknown:
        import difflib

        keys = ["val_split", "per_metric", "metrics", *sorted(set(types) - {"val_split"})]
        close = {k: difflib.get_close_matches(k, keys, n=1) for k in unknown}
        guess = "".join(f" ({k}: did you mean {m[0]}?)" for k, m in close.items() if m)
        raise RecipeError(f"recipe {name}: unknown key(s) {', '.join(unknown)}{guess}; recipe keys are {', '.join(keys)}",
                          unknown[0])
    return {k: _coerce(k, v, types[k]) for k, v in merged.items()}, val_split
