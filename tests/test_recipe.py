"""Training recipes: the shipped models' recipe ships with rtp and is recorded in the provenance."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from rtp.capture.scenes import map_names
from rtp.sdk import ParameterError
from rtp.train import SHIPPED_RECIPE, RecipeError, TrainConfig, load_recipe, packaged_recipes, train
from rtp.train.checkpoint import load as load_checkpoint

from .test_train import _dataset


def test_the_shipped_recipe_is_the_fast_network_for_every_metric() -> None:
    fl = load_recipe(SHIPPED_RECIPE, "flip")  # no per-metric special case but the measured ones
    # luma in place of the paper's red: measured for JNFLIP, JNYang and FLIP
    luma = ("reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "metallic", "specular")
    base = {"arch": "fast", "stem": 4, "width": 16, "depth": 3, "steps": 24000, "batch": 64, "crop": 64,
            "lr": 5e-4, "loss": "mse", "inputs": luma}
    blocks = (*luma, "reprojected.y.blocks", "albedo.y.blocks")
    # the luma's variance inside each rate's blocks: FLIP on the validation maps, then once on the test maps
    assert fl.values == {**base, "inputs": blocks}
    jn = load_recipe(SHIPPED_RECIPE, "jnyang")  # more, smaller crops won for JNYang, FLIP, JNFLIP (same pixels per step)
    # and twice as many of them for JNYang (measured on two seeds)
    # and a per-tile MLP head (two seeds on the validation maps, then the test maps and the closed loop)
    # and the luma's variance inside each rate's blocks (the validation maps, then the test maps and the loop)
    assert jn.values == {**base, "batch": 128, "head_width": 64, "inputs": blocks}
    # MSE made PSNR worse and tied JNFLIP: the paper's L1 (the .blocks planes saved JNFLIP no more on the test maps)
    assert load_recipe(SHIPPED_RECIPE, "jnflip").values == {**base, "loss": "l1"}
    old_crops = {"crop": 128, "batch": 16}  # PSNR: 64-pixel crops lost on the test maps; luma tied, red stays
    red = ("reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "metallic", "specular")
    # and the luma's variance inside each rate's blocks: PSNR on the validation maps, then once on the test maps
    assert load_recipe(SHIPPED_RECIPE, "psnr").values == {**base, **old_crops, "loss": "l1",
                                                           "inputs": (*red, "reprojected.y.blocks", "albedo.y.blocks")}
    lp = load_recipe(SHIPPED_RECIPE, "lpips")  # the material inputs did not help LPIPS; depth 5 did;
    # 64-pixel crops lost, 64 crops of 128 pixels a step won (its `head: linear` was never read by the fast network)
    assert lp.values == {**base, "crop": 128, "batch": 64,
                         "inputs": ("reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "albedo.g",
                                          "albedo.b", "normal.z"), "depth": 5}
    assert jn.val_split == "validation" and len(jn.sha256) == 64


def test_the_paper_network_recipe_ships_by_name() -> None:
    from rtp.train import packaged_recipes

    assert packaged_recipes()[0] == SHIPPED_RECIPE and "paper-net" in packaged_recipes()
    jn = load_recipe("paper-net", "jnyang")
    lp = load_recipe("paper-net", "lpips")
    assert jn.name == "paper-net" and jn.values == {"steps": 4000, "batch": 16, "crop": 128, "lr": 5e-4, "head": "paper"}
    assert lp.values["head"] == "linear" and {k: v for k, v in lp.values.items() if k != "head"} == {
        k: v for k, v in jn.values.items() if k != "head"}


def test_the_reuse_recipe_is_the_one_jnyang_reuse_was_trained_with() -> None:
    from rtp import sdk

    recipe = load_recipe("reuse", "jnyang")
    trained = sdk.load("jnyang-reuse").metadata.provenance["recipe"]  # the shipped recipe and its flags
    want = {**trained["values"], **trained.get("overrides", {})}

    def plain(values: dict) -> dict:
        return {k: list(v) if isinstance(v, (tuple, list)) else v for k, v in values.items()}

    assert plain(recipe.values) == plain(want)
    assert recipe.val_split == trained["val_split"] == "validation"
    assert recipe.values["contrast_max"] is True  # a bool key
    with pytest.raises(RecipeError, match="recipe reuse is for jnyang .*got metric 'flip'"):
        load_recipe("reuse", "flip")  # measured for JNYang only


def test_the_8_pixel_recipe_is_the_shipped_one_on_8_pixel_tiles() -> None:
    """tile8 is each shipped model's metric's recipe with ``tile: 8`` and nothing else but JNYang's measured
    narrower read of the frame, and every shipped ``-8px`` model was trained with it (the one file trains
    jnyang-8px, flip-8px, psnr-8px and jnflip-8px, and the LPIPS model that tied the split one and does not ship)."""
    from rtp import sdk

    metrics = ("jnyang", "flip", "psnr", "jnflip", "lpips")  # (the five that models ship for)
    measured = {"jnyang": {"width": 8, "tail_width": 24}}  # docs/results.md "Half the width where the frame is read"
    for metric in metrics:
        eight = load_recipe("tile8", metric)
        assert eight.val_split == load_recipe(SHIPPED_RECIPE, metric).val_split == "validation"
        want = {**load_recipe(SHIPPED_RECIPE, metric).values, "tile": 8, **measured.get(metric, {})}
        assert eight.values == want, metric
    for metric in set(sdk.METRICS) - set(metrics):
        with pytest.raises(RecipeError, match=f"recipe tile8 is for {', '.join(metrics)} .*got metric '{metric}'"):
            load_recipe("tile8", metric)
    models = [n.removesuffix(".onnx") for n in sdk.shipped_models() if n.endswith("-8px.onnx")]
    assert "jnyang-8px" in models
    for name in models:
        trained = sdk.load(name).metadata.provenance["recipe"]
        assert trained["name"] == "tile8" and trained["val_split"] == "validation", name
        given = {**trained["values"], **trained.get("overrides", {})}  # the recipe and the flags it was run with
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in given.items()}
        assert values == load_recipe("tile8", name.removesuffix("-8px")).values, name


def test_from_recipe_holds_out_the_split_and_flags_win(tmp_path: Path) -> None:
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out="o.pt", steps=10)
    assert cfg.steps == 10 and cfg.batch == 128 and cfg.crop == 64 and cfg.lr == 5e-4 and cfg.arch == "fast"
    assert cfg.head_width == 64  # JNYang's MLP head; every other metric keeps the linear read-out
    assert TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="flip", out="o.pt").head_width == 0
    assert cfg.val_split == "validation" and not cfg.val_scenes and map_names("validation")
    assert cfg.recipe is not None and cfg.recipe["name"] == SHIPPED_RECIPE and cfg.recipe["values"]["steps"] == 24000
    assert cfg.recipe["overrides"] == {"steps": 10}  # the provenance says what the command line changed
    same = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out="o.pt", crop=64)
    assert same.recipe is not None and "overrides" not in same.recipe  # the recipe's own value is no override


@pytest.mark.parametrize(("text", "needle"), [
    ("stepz: 10\n", "unknown key(s) stepz (stepz: did you mean steps?); recipe keys are val_split, per_metric, "
                     "metrics, arch,"),  # (val_split was listed twice)
    ("zzzzz: 1\n", "unknown key(s) zzzzz; recipe keys"),  # (no guess where none is close)
    ("steps: ten\n", "'steps': expected int"),
    ("steps: true\n", "'steps': expected int"),
    ("device: cuda\n", "'device' is the machine's, not the recipe's"),
    ("per_metric:\n  flip:\n    device: cpu\n  jnyang:\n    device: cuda\n", "'device' is the machine's"),
    ("lr: .nan\n", "'lr': expected a finite number, got nan"),
    ("inputs: 3\n", "'inputs': expected a list"),
    ("- 1\n- 2\n", "expected a mapping"),
    ("steps: [unclosed\n", "not valid YAML"),
    ("per_metric: 3\n", "per_metric must map"),
    # (a falsy value of the wrong type was taken as no section at all, silently)
    ("per_metric: []\n", "per_metric must map metric names to mappings of fields, got []"),
    ("per_metric: false\n", "per_metric must map metric names to mappings of fields, got False"),
    ("per_metric: ''\n", "per_metric must map metric names to mappings of fields, got ''"),
    ("val_split: 3\n", "'val_split': expected a split name"),
    ("metrics: jnyang\n", "'metrics': expected a list of metric names"),
    ("metrics: []\n", "'metrics': expected a list of metric names"),
    ("metrics: [flip]\n", "is for flip (measured for those only), got metric 'jnyang'"),
    ("augment: 1\n", "'augment': expected bool"),
    ("steps: true\n", "'steps': expected int"),
    ("device: cuda\n", "'device' is the machine's, not the recipe's"),
    ("per_metric:\n  flip:\n    device: cpu\n  jnyang:\n    device: cuda\n", "'device' is the machine's"),
    ("!!python/object/apply:os.system ['echo pwned']\n", "not valid YAML"),
    # per_metric: a typo'd metric, or a bad key of another metric's section, was never read (silently)
    ("per_metric:\n  jnyng:\n    batch: 4\n", "per_metric names unknown metric(s) jnyng (jnyng: did you mean jnyang?)"),
    ("per_metric:\n  psnr:\n    btach: 4\n", "r.yaml: unknown key(s) btach (btach: did you mean batch?)"),
    ("per_metric:\n  flip:\n    steps: '4'\n", "per_metric flip: recipe key 'steps': expected int, got '4'"),
    # the training's own fields: "unknown key(s) out (out: did you mean outputs?)", "val_scenes (... val_every?)"
    ("out: m.pt\n", "r.yaml: 'out' is the training's, not the recipe's: give it to the training (rtp train --out"),
    ("val_scenes: [scene0]\n", "(rtp train --val-scenes, TrainConfig.val_scenes); a recipe holds out the maps of a "
                               "split of scenes.yaml with val_split"),
    ("per_metric:\n  flip:\n    data: d\n", "'data' is the training's, not the recipe's: give it to the training "
                                            "(rtp train --data"),
    # a typo'd metric in `metrics` said "is for jnyng (measured for those only), got metric 'jnyang'"
    ("metrics: [jnyng, flip]\n", "metrics names unknown metric(s) jnyng (jnyng: did you mean jnyang?)"),
    # a top-level key inside a metric's section said "unknown key(s) metrics (metrics: did you mean metrics?)"
    ("per_metric:\n  jnyang:\n    metrics: [jnyang]\n", "r.yaml: per_metric jnyang sets 'metrics', a key of the "
                                                         "recipe's top level, not of a metric's section: move it out"),
    ("per_metric:\n  flip:\n    per_metric: {}\n", "per_metric flip sets 'per_metric', a key of the recipe's top level"),
])
def test_bad_recipes_are_refused_naming_the_key(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "r.yaml"
    path.write_text(text)
    with pytest.raises(RecipeError) as err:
        load_recipe(path, "jnyang")
    assert needle in str(err.value)
    assert isinstance(err.value, ParameterError)


@pytest.mark.parametrize(("text", "field"), [
    ("width: 1\n", "expected width >= 2"),
    ("crop: 40\n", "multiple of the tile size"),
    ("lr: -1.0\n", "lr: expected a finite learning rate > 0"),
    ("arch: paper\nseparable: true\n", "separable: the fast network's option"),
    # values the configuration never reads: recorded in the provenance and ignored, silently
    ("arch: paper\ndepth: 5\n", "sets depth: 5, which does not fit: depth: the fast network's option"),
    ("arch: paper\ngrow: 2\n", "sets grow: 2, which does not fit: grow: the fast network's option"),
    ("quantile: 0.9\n", "sets quantile: 0.9, read only with loss quantile"),
    ("logistic_k: 4\n", "sets logistic_k: 4.0, read only with transform logistic"),
    ("distill: 0.3\n", "sets distill: 0.3, read only with teachers"),
    ("aux_weight: 2\n", "sets aux_weight: 2.0, read only with aux_metrics"),
    ("schedule: cosine\nlr_decay: 0.001\n", "sets lr_decay: 0.001, read only with schedule exponential"),
])
def test_a_recipe_out_of_range_is_refused_when_read(tmp_path: Path, text: str, field: str) -> None:
    """Types are checked by load_recipe, ranges and combinations by TrainConfig.from_recipe: a recipe
    that train() would refuse is refused when read, before any data is looked for ("d" is none)."""
    path = tmp_path / "r.yaml"
    path.write_text(text)
    load_recipe(path, "jnyang")  # of the right types
    with pytest.raises(ParameterError, match=field):
        TrainConfig.from_recipe(path, data="d", metric="jnyang", out=str(tmp_path / "m.pt"))


def test_a_conflict_names_the_field_and_whether_the_recipe_or_the_caller_set_it(tmp_path: Path) -> None:
    out = str(tmp_path / "m.pt")
    # the paper's network ignored the fast network's depth, grow and stem_layers (and the provenance
    # recorded them as overrides); a value the caller gave is named as its own
    for key, value in (("depth", 9), ("grow", 2), ("stem_layers", 2), ("stem", 2)):
        with pytest.raises(ParameterError, match=f"^{key}: the fast network's option") as err:
            TrainConfig.from_recipe("paper-net", data="d", metric="psnr", out=out, **{key: value})
        assert err.value.name == key
    with pytest.raises(ParameterError, match="^quantile: read only with loss quantile") as err:
        TrainConfig.from_recipe("shipped", data="d", metric="psnr", out=out, quantile=0.9)
    assert err.value.name == "quantile"
    # a conflict with what the recipe set (not the caller) says so: rtp train --arch paper said
    # "--head-width: the fast network's option" of a --head-width never given
    with pytest.raises(ParameterError, match="^recipe shipped sets head_width: 64, which does not fit") as err:
        TrainConfig.from_recipe("shipped", data="d", metric="jnyang", out=out, arch="paper")
    assert err.value.name == "head_width"
    assert TrainConfig.from_recipe("shipped", data="d", metric="jnyang", out=out, arch="paper", head_width=0).depth == 3
    with pytest.raises(ParameterError, match="multiple of the tile size") as err:
        TrainConfig.from_recipe("shipped", data="d", metric="jnyang", out=out, crop=40)
    assert err.value.name == "crop"


@pytest.mark.parametrize(("text", "key"), [
    ("out: m.pt\n", "out"), ("val_scenes: [a]\n", "val_scenes"), ("per_metric:\n  flip:\n    data: d\n", "data"),
    ("metric: flip\n", "metric"), ("metrics: [jnyng]\n", "metrics"), ("metrics: [flip]\n", "metrics"),
    ("metrics: flip\n", "metrics"), ("per_metric: 3\n", "per_metric"), ("per_metric: []\n", "per_metric"),
    ("per_metric:\n  psnr:\n    metrics: [psnr]\n", "metrics"),
])
def test_a_bad_recipe_names_the_key_at_fault(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "r.yaml"
    path.write_text(text)
    with pytest.raises(RecipeError) as err:
        load_recipe(path, "jnyang")
    assert err.value.name == key


@pytest.mark.parametrize(("inputs", "got"), [
    ("[foo, seen]", "got unknown channel(s) 'foo'"), ("[seen, albedo.y, seen]", "got seen more than once"),
    ("[]", "got none"),
])
def test_recipe_inputs_are_channels_checked_when_read(tmp_path: Path, inputs: str, got: str) -> None:
    """An unknown channel failed as a DatasetError once the data was being read, a repeated one as a MetadataError
    at the first checkpoint save (steps into the training), none as torch's Conv2d's error naming no field."""
    path = tmp_path / "r.yaml"
    path.write_text(f"inputs: {inputs}\n")
    with pytest.raises(ParameterError, match=rf"^recipe .*r\.yaml sets inputs: .*expected one or more distinct "
                                             rf"channels among .*{re.escape(got)}") as err:
        TrainConfig.from_recipe(path, data="d", metric="jnyang", out=str(tmp_path / "m.pt"))
    assert err.value.name == "inputs"
    with pytest.raises(ParameterError, match=re.escape(got)) as err:  # train() itself, before any data ("d" is none)
        train(TrainConfig(data="d", metric="jnyang", out=str(tmp_path / "m.pt"), inputs=tuple(yaml.safe_load(inputs))))
    assert err.value.name == "inputs"


def test_the_callers_val_split_and_splits_win_over_the_recipes(tmp_path: Path) -> None:
    """Overrides win over the recipe, val_split and splits too: the recipe's val_split replaced the caller's, and the
    packaged split list (scenes=None) the splits file the caller or the recipe gave."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text("train: [scene0]\nvalidation: [scene1]\ntest: [scene2]\n")
    out = str(tmp_path / "m.pt")
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, val_split="test")
    assert cfg.val_split == "test" and cfg.recipe is not None and cfg.recipe["overrides"] == {"val_split": "test"}
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, val_split=None)
    assert cfg.val_split is None
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, val_split="validation")
    assert cfg.recipe is not None and "overrides" not in cfg.recipe  # (the recipe's own split is no override)
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, splits=str(splits))
    assert (cfg.val_split, cfg.splits) == ("validation", str(splits))
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, scenes=splits)
    assert (cfg.val_split, cfg.splits) == ("validation", str(splits))
    # a recipe's own val_split that is no split is the recipe's fault, named so; the caller's is the caller's
    bad = tmp_path / "bad.yaml"
    bad.write_text("val_split: validaton\n")
    with pytest.raises(RecipeError, match=r"^recipe .*bad\.yaml sets val_split: validaton, which does not fit") as err:
        TrainConfig.from_recipe(bad, data="d", metric="jnyang", out=out)
    assert err.value.name == "val_split"
    with pytest.raises(ParameterError, match="^val_split: split: expected one of train, validation, test") as err:
        TrainConfig.from_recipe(SHIPPED_RECIPE, data="d", metric="jnyang", out=out, val_split="validaton")
    assert err.value.name == "val_split"


def test_a_recipes_splits_file_holds_out_its_maps(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A recipe's ``splits`` was replaced by the packaged split list when it also set ``val_split``: the data's last
    scene was held out (with a warning that none of the validation maps was there) while the provenance recorded the
    recipe's splits file."""
    data = _dataset(tmp_path / "d")  # scenes scene0..scene2
    splits = tmp_path / "scenes.yaml"
    splits.write_text("train: [scene0, scene2]\nvalidation: [scene1]\ntest: []\n")
    recipe = tmp_path / "r.yaml"
    recipe.write_text(f"val_split: validation\nsplits: {splits}\nsteps: 2\nbatch: 2\ncrop: 32\n")
    cfg = TrainConfig.from_recipe(recipe, data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"))
    with caplog.at_level("WARNING", logger="rtp"):
        train(cfg)
    assert "holds none of the validation maps" not in caplog.text
    prov = load_checkpoint(tmp_path / "m.pt").metadata.provenance
    assert list(prov["val_scenes"]) == ["scene1"] and prov["recipe"]["values"]["splits"] == str(splits)


def test_splits_without_a_val_split_is_refused_not_ignored(tmp_path: Path) -> None:
    """``splits`` is read only to hold out ``val_split``'s maps: a recipe's ``splits`` without ``val_split`` (or
    ``rtp train --splits`` with such a recipe) was recorded in the checkpoint and ignored, the data's last scene held
    out instead of the file's validation maps. It is refused, naming what reads it; with val_split or val_scenes it
    is taken."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text("train: [scene0, scene2]\nvalidation: [scene1]\ntest: []\n")
    out = str(tmp_path / "m.pt")
    recipe = tmp_path / "r.yaml"
    recipe.write_text(f"splits: {splits}\nsteps: 2\n")
    with pytest.raises(RecipeError, match=r"^recipe .*r\.yaml sets splits: .*read only with val_split.*add val_split "
                                          r"to the recipe") as err:
        TrainConfig.from_recipe(recipe, data="d", metric="jnyang", out=out)
    assert err.value.name == "splits"
    plain = tmp_path / "plain.yaml"
    plain.write_text("steps: 2\n")
    for given in ({"scenes": splits}, {"splits": str(splits)}):  # the caller's (rtp train --splits), likewise
        with pytest.raises(ParameterError, match="^splits: read only with val_split") as err:
            TrainConfig.from_recipe(plain, data="d", metric="jnyang", out=out, **given)  # type: ignore[arg-type]
        assert err.value.name == "splits"
    with pytest.raises(ParameterError, match="^splits: read only with val_split") as err:  # train() itself, no data read
        train(TrainConfig(data="d", metric="jnyang", out=out, splits=str(splits)))
    assert err.value.name == "splits"
    # with a split to hold out, or the caller's own validation scenes (which win), it is taken
    cfg = TrainConfig.from_recipe(recipe, data="d", metric="jnyang", out=out, val_split="validation")
    assert (cfg.val_split, cfg.splits) == ("validation", str(splits))
    assert TrainConfig.from_recipe(recipe, data="d", metric="jnyang", out=out, val_scenes=("scene1",)).val_scenes == (
        "scene1",)


def test_a_missing_recipe_names_the_packaged_ones(tmp_path: Path) -> None:
    with pytest.raises(RecipeError, match="shipped, paper-net"):
        load_recipe(tmp_path / "nope.yaml", "jnyang")


def test_a_packaged_recipe_reads_the_same_under_any_locale() -> None:
    """A packaged recipe is UTF-8 (the R² of its comments), read as a user's recipe file is: under an ASCII locale
    (LC_ALL=C without Python's UTF-8 mode) load_recipe('shipped') failed with a bare UnicodeDecodeError, and under
    cp1252 or Latin-1 it read other text, so another digest went into the model's provenance."""
    from importlib import resources

    files = {name: resources.files("rtp.train").joinpath(f"recipes/{name}.yaml").read_bytes()
             for name in packaged_recipes()}
    assert any(not data.isascii() for data in files.values())  # (else this checks nothing)
    want = {name: hashlib.sha256(data).hexdigest() for name, data in files.items()}
    code = ("import json; from rtp.train import load_recipe, packaged_recipes; "
            "print(json.dumps({n: load_recipe(n, 'jnyang' if n == 'reuse' else 'flip').sha256 for n in packaged_recipes()}))")
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.splitlines()[-1]) == want
    assert {n: load_recipe(n, "jnyang" if n == "reuse" else "flip").sha256 for n in files} == want


def test_the_recipe_is_recorded_in_the_model(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "d")
    recipe = tmp_path / "r.yaml"
    recipe.write_text("steps: 6\nbatch: 2\ncrop: 32\nhead: linear\nval_every: 3\nsave_every: 3\n")
    cfg = TrainConfig.from_recipe(recipe, data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"))
    train(cfg)
    prov = load_checkpoint(tmp_path / "m.pt").metadata.provenance
    assert prov["recipe"]["name"] == str(recipe) and prov["recipe"]["values"]["crop"] == 32


def test_the_recipe_split_falls_back_to_the_last_scene(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    data = _dataset(tmp_path / "d")  # scenes scene0..scene2: none of them a validation map
    cfg = TrainConfig.from_recipe(SHIPPED_RECIPE, data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"),
                                  steps=2, batch=2, crop=32)
    with caplog.at_level("WARNING", logger="rtp"):
        train(cfg)
    assert "holds none of the validation maps" in caplog.text
    assert list(load_checkpoint(tmp_path / "m.pt").metadata.provenance["val_scenes"]) == ["scene2"]
