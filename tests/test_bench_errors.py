"""The benchmark scripts and examples follow rtp's error policy (docs/errors.md): bad arguments are
argparse's usage errors, and an rtp error found while running (a model, map or dataset that is not
there) prints one line, ``NAME.py: error: ...``, with rtp's exit code, instead of a traceback."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import BENCH

ROOT = Path(__file__).resolve().parents[1]


def test_every_script_runs_its_main_under_the_error_policy() -> None:
    """Each bench script's ``__main__`` block is ``run_main(...)`` (bench/_common.py), and no script
    prints its own "error: ..." line (they had three formats, some without the program's name)."""
    for path in sorted(BENCH.glob("*.py")):
        if path.name == "_common.py":
            continue
        tree = ast.parse(path.read_text())
        blocks = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
        assert blocks and "run_main(" in ast.unparse(blocks[0]), f"{path.name}: its __main__ is not run_main(...)"
        assert '"error: ' not in path.read_text(), f"{path.name} prints its own error line"


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(("args", "code", "words"), [
    (["bench/inference.py", "nosuchmodel"], 2, "inference.py: error: no model file at 'nosuchmodel'"),
    (["bench/inference.py", "--repeats", "0"], 2, "argument --repeats: expected a positive integer"),
    (["bench/budget.py", "--model", "nosuchmodel"], 2, "budget.py: error: no model file at 'nosuchmodel'"),
    (["bench/budget.py", "--saving", "0.99"], 2, "budget.py: error: argument --saving: expected a finite number in "
                                                 "[0, 0.9375], got '0.99'"),
    (["bench/paths.py", "--size", "12x"], 2, "argument --size: expected WIDTHxHEIGHT"),
    (["bench/paths.py", "--maps", "nosuchmap", "--frames", "3"], 2, "paths.py: error: map 'nosuchmap' is not listed"),
    (["bench/scaling.py", "--modes", "nosuch"], 2, "argument --modes: expected ray and/or pool"),
    (["bench/report.py", "README.md"], 2, "is not JSON"),
    # input_ceiling.py runs ``rtp train`` in-process: its own parser refuses what that one would
    (["bench/input_ceiling.py", "--metric", "nosuch"], 2, "input_ceiling.py: error: argument --metric"),
    (["examples/moderngl_vrs.py", "--model", "nosuch"], 2, "moderngl_vrs.py: error: no model file at 'nosuch'"),
    # numbers a run would choke on (NaN into time.sleep, a share of 5) are usage errors, and what a later table
    # reads is checked before the first table's minutes
    (["bench/spinning.py", "--long-ms", "nan"], 2, "argument --long-ms: expected a finite number in [0, 60000]"),
    (["bench/spinning.py", "--model", "nosuch"], 2, "spinning.py: error: no model file at 'nosuch'"),
    (["bench/views.py", "--seconds", "inf"], 2, "argument --seconds: expected a finite number in (0, 600]"),
    (["bench/views.py", "--size", "1x1"], 2, "argument --size: expected WIDTHxHEIGHT of at least 16x16"),
    (["bench/hardware_tiles.py", "jnyang", "--fail-share", "5"], 2, "argument --fail-share: expected a finite number "
                                                                   "in (0, 1)"),
    (["bench/per_rate.py", "jnyang", "--fit", "nan"], 2, "argument --fit: expected a finite number in (0, 1)"),
    # a child's error and git's are one line of this script's, exit 2 (exit 1 and a line naming two programs before)
    (["bench/memory.py", "/nope.onnx"], 2, "memory.py: error: no model file at '/nope.onnx'"),
    (["bench/input_planes.py", "--against", "nosuchrev"], 2, "input_planes.py: error: --against nosuchrev: git "
                                                             "cannot show"),
    # worker counts were read after part 1's timings: a ValueError traceback for "x", compute_targets' refusal for 0
    (["bench/targets.py", "--workers", "1,x"], 2, "targets.py: error: argument --workers: expected a positive integer, "
                                                  "got 'x'"),
    (["bench/scaling.py", "--workers", "0"], 2, "scaling.py: error: argument --workers: expected a positive integer"),
])
def test_bad_input_is_one_line(args: list[str], code: int, words: str) -> None:
    run = _run(args, ROOT)
    assert run.returncode == code, run.stderr
    assert "Traceback" not in run.stderr and words in run.stderr.strip().splitlines()[-1], run.stderr


#: Runs each bench script given with ``--help`` where the optional modules of rtp's extras cannot be imported, each
#: in this one process (its ``SystemExit`` caught, its output kept), and prints what each said as JSON.
_WITHOUT_EXTRAS = """
import contextlib, io, json, runpy, sys
for m in ("torch", "tqdm", "onnx", "matplotlib", "flip_evaluator", "moderngl", "pyrender", "ray", "PIL", "png",
          "trimesh", "imageio", "scipy"):
    sys.modules[m] = None  # (an import of it raises ImportError, as where it is not installed)
sys.path.insert(0, "bench")
said = {}
for script in sys.argv[1:]:
    sys.argv = [script, "--help"]
    out, err, code = io.StringIO(), io.StringIO(), None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            runpy.run_path(script, run_name="__main__")
        except SystemExit as exc:
            code = exc.code
        except BaseException as exc:
            code, err = "raised", io.StringIO(f"{type(exc).__name__}: {exc}")
    said[script] = [code, out.getvalue(), err.getvalue()]
print(json.dumps(said))
"""


def test_help_without_the_extras_is_the_help_or_one_line_naming_the_install() -> None:
    """`python bench/X.py --help` without torch, tqdm or onnx (the train, capture and export extras) was a
    ModuleNotFoundError traceback in 17 scripts that import them when they start; each now prints its help or
    says in one line what to install (exit 2, a missing install: docs/errors.md)."""
    scripts = sorted(f"bench/{p.name}" for p in BENCH.glob("*.py") if not p.name.startswith("_"))
    run = subprocess.run([sys.executable, "-c", _WITHOUT_EXTRAS, *scripts], cwd=ROOT, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    said = json.loads(run.stdout.strip().splitlines()[-1])
    needs = {}
    for script, (code, out, err) in said.items():
        name = Path(script).name
        if code == 0:
            assert out.startswith("usage: "), (script, out, err)
            continue
        assert code == 2 and not out and err.count("\n") == 1, (script, code, err)
        assert err.startswith(f"{name}: error: this script needs "), (script, err)
        needs[name] = err.split()[5].rstrip(",")
    # (one of each: tqdm's bars, torch itself, torch through rtp.train, onnx)
    assert {needs.get(s) for s in ("per_rate.py", "inference.py", "study.py", "inference_gpu.py")} == {
        "tqdm", "torch", "onnx"}, needs
    assert "pip install 'rtp[train]'" in said["bench/inference.py"][2]


def test_a_json_of_another_kind_and_a_folder_that_is_not_a_dataset(tmp_path: Path) -> None:
    (tmp_path / "other.json").write_text(json.dumps({"settings": {}, "matched": []}))
    run = _run([str(BENCH / "play_report.py"), str(tmp_path / "other.json")], tmp_path)
    assert run.returncode == 2 and "is not a play.json (the file `rtp play --out DIR` writes)" in run.stderr
    # the right keys with other kinds of value: a usage error too, not a TypeError once the tables are made
    (tmp_path / "odd.json").write_text(json.dumps({"settings": {"scene": 1}, "rows": 5, "matched": 3}))
    run = _run([str(BENCH / "play_report.py"), str(tmp_path / "odd.json")], tmp_path)
    assert run.returncode == 2 and "is not a play.json" in run.stderr and "Traceback" not in run.stderr, run.stderr
    (tmp_path / "odd.json").write_text(json.dumps({"model": 5, "quality": [1], "decisions": "x"}))
    run = _run([str(BENCH / "report.py"), str(tmp_path / "odd.json")], tmp_path)
    assert run.returncode == 2 and "is not an evaluation.json" in run.stderr and "Traceback" not in run.stderr, run.stderr
    (tmp_path / "fake").mkdir()
    (tmp_path / "fake" / "manifest.json").write_text(json.dumps({"format": "mine"}))
    run = _run([str(BENCH / "outputs.py"), "jnyang", "--data", str(tmp_path / "fake")], tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr and "argument --data" in run.stderr, run.stderr


def test_the_out_folder_of_play_and_evaluate_is_read_as_its_report(tmp_path: Path) -> None:
    """`rtp play --out play` then `bench/play_report.py play` (and `rtp evaluate --out eval`, `bench/report.py eval`)
    was refused, "'play': Is a directory"; the folder's play.json / evaluation.json is read now, and a folder without
    one is named as such."""
    import argparse

    from .conftest import bench_module

    common = bench_module("_common")
    (tmp_path / "play").mkdir()
    (tmp_path / "play" / "play.json").write_text(json.dumps({"settings": {}, "rows": []}))
    assert common.PLAY_JSON(str(tmp_path / "play")) == tmp_path / "play" / "play.json"
    (tmp_path / "eval").mkdir()
    (tmp_path / "eval" / "evaluation.json").write_text(json.dumps([{"model": {}, "quality": [], "decisions": []}]))
    assert common.EVALUATION_JSON(str(tmp_path / "eval")) == tmp_path / "eval" / "evaluation.json"
    with pytest.raises(argparse.ArgumentTypeError, match="is a folder without evaluation.json in it"):
        common.EVALUATION_JSON(str(tmp_path / "play"))
    with pytest.raises(argparse.ArgumentTypeError, match="is not a play.json"):  # (the folder's file is checked too)
        common.PLAY_JSON(str(tmp_path / "eval" / "evaluation.json"))


def test_input_ceiling_checks_its_maps_before_the_training_they_come_after(tmp_path: Path) -> None:
    """--scene is read after hours of training: a map the dataset does not hold is refused first."""
    from rtp.capture import capture

    capture(["procedural:3"], tmp_path / "d", per_scene=1, size=(64, 48))
    for scene, words in (("nosuchmap", "--scene: nosuchmap not in"), (",", "--scene: expected comma-separated map")):
        run = _run([str(BENCH / "input_ceiling.py"), "--metric", "flip", "--data", str(tmp_path / "d"),
                    "--scene", scene, "--out", str(tmp_path / "m.pt")], tmp_path)
        assert run.returncode == 2 and words in run.stderr and "Traceback" not in run.stderr, run.stderr
        assert not list(tmp_path.glob("*m.pt*")), scene  # no training began


@pytest.mark.parametrize(("args", "words"), [
    (["bench/budget.py", "--saving", "1.5"], "budget.py: error: argument --saving: expected a finite number in "
                                             "[0, 0.9375], got '1.5'"),
    (["bench/budget.py", "--model", "nosuchmodel"], "budget.py: error: no model file at 'nosuchmodel'"),
    (["bench/paths.py", "--maps", "nosuchmap", "--frames", "3"], "paths.py: error: map 'nosuchmap' is not listed"),
    # one frame has no second to be unseen in: "Mean of empty slice", then an IndexError, after the header
    (["bench/paths.py", "--maps", "procedural:0", "--frames", "1", "--size", "160x96"],
     "paths.py: error: argument --frames: expected an integer >= 2, got 1"),
    (["bench/paths.py", "--maps", ",", "--frames", "3"], "paths.py: error: --maps: expected comma-separated map names"),
    # rtp play's first frame has no history: its "--frames: expected ... at least 3" came after the jobs before it
    (["bench/job_memory.py", "--frames", "2"], "job_memory.py: error: argument --frames: expected an integer >= 3, got 2"),
    # sys.setswitchinterval(inf) sets an interval of 0 (the table then said "inf"); NaN failed after the first table
    (["bench/views.py", "--switch", "0.005,inf"], "views.py: error: --switch: expected comma-separated seconds in (0, 1]"),
    (["bench/views.py", "--switch", "nan"], "views.py: error: --switch: expected comma-separated seconds in (0, 1]"),
    (["bench/views.py", "nosuchmodel"], "views.py: error: no model file at 'nosuchmodel'"),
    # a map not listed (or not fetched) came after the table's header, and after Ray's start
    (["bench/scaling.py", "--scenes", "procedural:0,nosuchmap", "--modes", "pool"],
     "scaling.py: error: map 'nosuchmap' is not listed"),
    (["bench/scaling.py", "--scenes", ","], "scaling.py: error: --scenes: expected comma-separated scene names"),
    (["bench/scaling.py", "--scenes", "procedural:0,procedural:0", "--modes", "pool"],
     "scaling.py: error: --scenes: each scene once, got procedural:0 more than once"),
    # a map not listed came after the maps named before it were converted (minutes each)
    (["bench/scenes.py", "--maps", "oa_dm5,nosuchmap"], "scenes.py: error: map 'nosuchmap' is not listed"),
    (["bench/scenes.py", "--maps", ","], "scenes.py: error: --maps: expected comma-separated map names"),
    # levels and sizes the kit cannot draw, refused before the first of its checks (seconds each)
    (["bench/conformance_margins.py", "--levels", "4-2"], "conformance_margins.py: error: argument --levels: "
                                                          "expected comma-separated seeds >= 0 or ranges A-B"),
    (["bench/conformance_margins.py", "--levels", "0,1,0-2"], "conformance_margins.py: error: argument --levels: "
                                                              "each level once, got 0, 1 more than once"),
    (["bench/conformance_margins.py", "--sizes", "64x48,8x8"], "conformance_margins.py: error: argument --sizes: "
                                                               "expected WIDTHxHEIGHT of at least 16x16"),
    # a fast network build_network refuses was a bare SystemExit (exit 1) after the header; a model name that is
    # none came after the header and the models profiled before it
    (["bench/ort_profile.py", "--fast", "width=0", "--size", "64x64"], "ort_profile.py: error: --fast width=0: "
                                                                        "expected width >= 2"),
    (["bench/ort_profile.py", "jnyang", "nosuchmodel", "--size", "64x64"], "ort_profile.py: error: no model file at "
                                                                           "'nosuchmodel'"),
])
def test_bad_input_is_refused_before_any_table(args: list[str], words: str) -> None:
    """What a script cannot do is said before its table's header (the header, then the error, read as a
    table of no rows) and before its long work."""
    run = _run(args, ROOT)
    assert run.returncode == 2 and run.stdout == "", (run.stdout, run.stderr)
    assert "Traceback" not in run.stderr and words in run.stderr.strip().splitlines()[-1], run.stderr


def test_a_dataset_without_what_a_script_reads_is_refused_before_its_table(tmp_path: Path) -> None:
    """outputs.py printed its header, then failed on the first missing targets; error_features.py read every
    sample of one map before saying it needs two; combine.py read them all before refusing a saving of 2."""
    from rtp.capture import capture, compute_targets

    capture(["procedural:0", "procedural:1"], tmp_path / "d", per_scene=1, size=(64, 48))
    data = str(tmp_path / "d")
    for args, words in (
            (["outputs.py", "lpips", "--data", data], f"outputs.py: error: {data} has no lpips targets for lpips (it has "
                                                      f"none): run `rtp targets {data} --metrics lpips`"),
            (["combine.py", "jnyang", "--data", data, "--scene", "procedural:0"],
             f"combine.py: error: {data} has no jnyang targets for jnyang (it has none)"),
            # ensemble.py, hardware_tiles.py and per_rate.py read the targets sample by sample: the error came under a
            # progress bar (per_rate.py's after predicting every sample)
            (["ensemble.py", "jnyang", "--data", data], f"ensemble.py: error: {data} has no jnyang targets"),
            (["hardware_tiles.py", "jnyang", "--data", data, "--scene", "procedural:0"],
             f"hardware_tiles.py: error: {data} has no jnyang targets"),
            (["per_rate.py", "jnyang", "--data", data, "--scene", "procedural:0,procedural:1"],
             f"per_rate.py: error: {data} has no jnyang targets"),
            ("targets", ""),  # (the rest read a dataset with them)
            (["combine.py", "jnyang", "--data", data, "--scene", "procedural:0", "--savings", "0.5,2"],
             "combine.py: error: --savings: expected shares of the shading work to save, each in [0, 0.9375]"),
            (["error_features.py", "jnyang", "--data", data, "--scene", "procedural:0"],
             "error_features.py: error: leave-one-map-out needs samples of at least two maps, got ['procedural:0']"),
            # per_rate.py: a map twice had no other map to fit on (a numpy traceback); a map without samples was
            # found once every sample of the others was predicted
            (["per_rate.py", "jnyang", "--data", data, "--scene", "procedural:0,procedural:0"],
             "per_rate.py: error: --scene: expected distinct maps, got 'procedural:0,procedural:0'"),
            (["per_rate.py", "jnyang", "--data", data, "--scene", "procedural:0,nosuchmap"],
             f"per_rate.py: error: {data} holds no sample of nosuchmap"),
            # two files of other tiles: a numpy broadcast traceback under the progress bar
            (["same_decisions.py", "jnyang", "jnyang-8px", "--data", data],
             "same_decisions.py: error: the two files are not one model")):
        if args == "targets":
            compute_targets(data, ("jnyang",))
            continue
        run = _run([str(BENCH / args[0]), *args[1:]], tmp_path)
        assert run.returncode == 2 and run.stdout == "" and "Traceback" not in run.stderr, (args, run.stdout, run.stderr)
        # one line: no progress bar of samples read before it
        assert len(run.stderr.strip().splitlines()) == 1 and run.stderr.startswith(words), run.stderr


def test_loop_scale_refuses_a_one_threshold_model_that_is_not_one(tmp_path: Path) -> None:
    """--one is the same model with one threshold: a baseline (yang2019), --method itself, another metric's model
    or a model with factors per rate gave scale factors that mean nothing; each is refused in one line."""
    run_json = tmp_path / "play.json"
    run_json.write_text(json.dumps({"settings": {"scene": "a", "methods": ["jnyang", "flip", "jnyang-8px", "yang2019"],
                                                 "models": {"jnyang": "jnyang", "flip": "flip", "jnyang-8px": "jnyang-8px"}},
                                    "unseen": {"fast": [1.0, 0.1]}, "rows": []}))
    for method, one, words in (
            ("jnyang-8px", "yang2019", "--one: 'yang2019' is a baseline, not a model with thresholds"),
            ("yang2019", "jnyang-8px", "--method: 'yang2019' is a baseline, not a model with thresholds"),
            ("jnyang-8px", "nosuch", "--one: the runs hold no model 'nosuch'; the runs hold the models jnyang, flip, "
                                     "jnyang-8px"),
            ("jnyang-8px", "jnyang-8px", "--one: expected the model with one threshold, another file than --method"),
            ("jnyang-8px", "flip", "--one: expected the same model with one threshold; flip predicts flip, jnyang-8px "
                                   "jnyang"),
            ("jnyang-8px", "jnyang", "--one: expected the model with one threshold (`rate_factors: null`), got jnyang "
                                     "with factors per rate")):
        run = _run([str(BENCH / "loop_scale.py"), str(run_json), "--method", method, "--one", one], tmp_path)
        assert run.returncode == 2 and run.stdout == "" and "Traceback" not in run.stderr, run.stderr
        assert run.stderr.strip().startswith(f"loop_scale.py: error: {words}"), run.stderr


def test_play_report_shows_how_near_a_target_a_figure_is() -> None:
    """The report rounded 89.85% of the oracle's saving to "90%" and 0.9945x Yang's to "1.00x": both read as
    targets met (>= 90%, >= 1.0x) that were missed."""
    from .conftest import bench_module

    fmt = bench_module("play_report")._fmt
    assert fmt(0.8985, pct=True) == "89.8%" and fmt(1.024, pct=True) == "102.4%"
    assert fmt(0.9945) == "0.995x" and fmt(1.0049) == "1.005x" and fmt(1.52) == "1.52x" and fmt(0.97) == "0.97x"
    assert fmt(float("nan")) == "-" and fmt(float("inf"), pct=True) == "-"


def test_the_inference_bench_checks_its_models_before_timing(monkeypatch: pytest.MonkeyPatch) -> None:
    """`bench/inference.py nosuchmodel` timed the paper's network and every shipped model, a minute or more, before
    saying the file was not there: it is loaded first."""
    from rtp import sdk

    from .conftest import bench_module

    mod = bench_module("inference", monkeypatch)

    def timed(*args: object, **kwargs: object) -> None:
        raise AssertionError("the bench timed a network before loading the models it was given")

    monkeypatch.setattr(mod, "paper_model", timed)
    monkeypatch.setattr(sys, "argv", ["inference.py", "nosuchmodel"])
    with pytest.raises(sdk.ModelNotFoundError, match="nosuchmodel"):
        mod.main()


def test_published_checks_what_its_rows_read_before_the_first(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """published.py said "holds no samples of the validation maps" as a bare SystemExit (exit 1, no program name),
    and a metric's targets or a published file missing came after the table's header and the rows before it."""
    from rtp.capture import capture, compute_targets

    from .conftest import bench_module

    capture(["procedural:0"], tmp_path / "d", per_scene=1, size=(64, 48))
    compute_targets(tmp_path / "d", ("jnyang",))
    data = str(tmp_path / "d")
    mod = bench_module("published", monkeypatch)
    monkeypatch.setattr(sys, "argv", ["published.py", "--data", data, "--data-l0", data])
    with pytest.raises(mod.UsageError, match="holds no samples of the validation maps"):
        mod.main()
    monkeypatch.setattr(mod, "load_splits", lambda: {"validation": ["procedural:0"]})
    with pytest.raises(mod.UsageError, match=f"{data} has no flip targets for flip"):
        mod.main()
    (tmp_path / "models").mkdir()
    monkeypatch.setattr(sys, "argv", [*sys.argv, "--models", str(tmp_path / "models")])
    with pytest.raises(mod.UsageError, match="--models: .* has no FLIP.onnx, JNYang.onnx, LPIPS.onnx, PSNR.onnx"):
        mod.main()
    assert capsys.readouterr().out == ""


def test_published_measures_the_shipped_model_as_it_decides(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """published.py's "rtp model" column, the failing share the published models' thresholds are fitted to, chose
    the shipped model's rates with one threshold: since the shipped models carry thresholds per rate (`rate_factors`)
    it was not the model at its default (flip on data/val720: 9.8% failing / 49.2% saved, where the model's own
    decisions fail on 8.0% and save 50.4%; the published FLIP's threshold fitted to it 0.14, not 0.1218). It is
    measured on the rates `shading_rates` gives now."""
    from rtp import sdk
    from rtp.capture import DatasetReader, TargetStore, capture, compute_targets
    from rtp.evaluate import failing_tiles

    from .conftest import bench_module

    capture(["procedural:0"], tmp_path / "d", per_scene=2, size=(256, 160))
    compute_targets(tmp_path / "d", ("jnyang",))
    data = str(tmp_path / "d")
    mod = bench_module("published", monkeypatch)
    monkeypatch.setattr(mod, "load_splits", lambda: {"validation": ["procedural:0"]})
    monkeypatch.setattr(mod, "FILES", {"jnyang": "JNYang.onnx"})
    monkeypatch.setattr(sys, "argv", ["published.py", "--data", data, "--data-l0", data])
    ours, reader, store = sdk.load("jnyang"), DatasetReader(data), TargetStore(data)
    meta = ours.metadata
    assert meta.rate_factors is not None and len(set(meta.rate_factors)) > 1
    shown = {}
    for factors in (meta.rate_factors, None):  # (what the model does, and one threshold: they differ here)
        fails = saved = n = 0.0
        for i in reader.ids:
            est = ours.predict(reader[i].inputs(meta.inputs))
            codes = sdk.select_rates(est, meta.default_threshold, factors=factors)
            fails += failing_tiles(codes, store.load(i, "jnyang", 16), meta.default_threshold, False).sum()
            saved += sdk.work_saved(codes, reader[i].size, 16) * codes.size
            n += codes.size
        shown[factors] = f"{100 * fails / n:.1f}% / {100 * saved / n:.1f}%"
    assert shown[meta.rate_factors] != shown[None], shown
    mod.main()
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| jnyang |"))
    assert row.split("|")[3].strip() == shown[meta.rate_factors], (row, shown)


def test_scaling_runs_the_pool_without_ray_and_names_the_extra_for_ray(monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """scaling.py imported Ray at its top: `--modes pool` (docs/scaling.md) failed without the ray extra, and
    `--modes ray` with a ModuleNotFoundError traceback instead of naming `pip install 'rtp[ray]'`."""
    from .conftest import bench_module

    monkeypatch.setitem(sys.modules, "ray", None)  # (`import ray` raises ImportError)
    mod = bench_module("scaling", monkeypatch)
    monkeypatch.setattr(sys, "argv", ["scaling.py", "--scenes", "procedural:0", "--modes", "ray"])
    with pytest.raises(mod.UsageError, match=r"--modes ray needs Ray: pip install 'rtp\[ray\]'"):
        mod.main()
    assert capsys.readouterr().out == ""  # (before the table)
    monkeypatch.setattr(mod, "run", lambda *args: (2.0, 4.0, 6))
    monkeypatch.setattr(sys, "argv", ["scaling.py", "--scenes", "procedural:0", "--modes", "pool", "--workers", "1,2"])
    mod.main()
    out = capsys.readouterr().out
    assert "| process pool | 1 | 2.00 | 4.00 | 1.00x | 1.00x | 0.0 |" in out and "ray" not in out.split("\n")[0], out


def test_the_inference_bench_keeps_two_models_of_one_file_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`bench/inference.py data/old/jnyang.onnx data/joined/jnyang.onnx` keyed both by "jnyang.onnx": the second
    replaced the first and the table had one row, with no word of the other."""
    import shutil

    from rtp import sdk

    from .conftest import bench_module

    mod = bench_module("inference", monkeypatch)
    shipped = Path(str(sdk.load("jnyang").path))
    monkeypatch.setattr(mod, "paper_model", lambda *args, **kwargs: (None, shipped))
    monkeypatch.setattr(mod, "FAST", ())
    monkeypatch.setattr(mod.sdk, "shipped_models", lambda: [])
    given = []
    for folder in ("old", "joined"):
        (tmp_path / folder).mkdir()
        given.append(str(shutil.copy(shipped, tmp_path / folder / "jnyang.onnx")))
    other = str(shutil.copy(shipped, tmp_path / "other.onnx"))
    models = mod._models(tmp_path, 1, [*given, other, other])
    assert list(models) == ["paper's network (random weights)", *given, "other.onnx"], list(models)
    assert [str(p.path) for p, _ in list(models.values())[1:3]] == given


def test_the_inference_bench_times_a_shipped_model_given_by_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`bench/inference.py jnyang` (a shipped model's name, as every rtp command takes it) passed the check before
    timing, then, after the timing, read its parameters from a file `jnyang` in the working folder: "No such file or
    directory: 'jnyang'". Its row is read from the file sdk.load finds."""
    from rtp import sdk

    from .conftest import bench_module

    mod = bench_module("inference", monkeypatch)
    shipped = Path(str(sdk.load("jnyang").path))
    monkeypatch.setattr(mod, "paper_model", lambda *args, **kwargs: (None, shipped))
    monkeypatch.setattr(mod, "FAST", ())
    monkeypatch.setattr(mod.sdk, "shipped_models", lambda: [])
    monkeypatch.chdir(tmp_path)
    models = mod._models(tmp_path, 1, ["jnyang"])
    assert list(models) == ["paper's network (random weights)", "jnyang"], list(models)
    assert str(models["jnyang"][0].path) == str(shipped) and models["jnyang"][1] == ("fast", mod._params(shipped))


def test_hardware_tiles_says_where_its_sweep_ends_instead_of_reading_its_last_point() -> None:
    """bench/hardware_tiles.py read the saving at 10% failing tiles off a sweep that never failed that often as the
    sweep's last point, printed plain (a lower bound read as the figure), and ``--fail-share S`` of a sweep that never
    failed on S as the sweep's end threshold (``np.interp`` clamps): 4x the judging threshold, printed as the
    threshold failing on S. The first is marked ">=" now (as bench/report.py marks it), the second is "-" with the
    shares the sweep covers."""
    import numpy as np

    from .conftest import bench_module

    mod = bench_module("hardware_tiles")
    fails, saved = np.array([0.015, 0.03, 0.06]), np.array([0.40, 0.50, 0.60])
    assert mod.saved_cells(fails, saved, (0.01, 0.02, 0.05, 0.10)) == ["-", "43.3", "56.7", ">= 60.0"]
    thresholds = [0.1, 0.2, 0.3]
    assert mod.threshold_at(fails, thresholds, 0.045) == "0.25"
    assert mod.threshold_at(fails, thresholds, 0.015) == "0.1" and mod.threshold_at(fails, thresholds, 0.06) == "0.3"
    assert mod.threshold_at(fails, thresholds, 0.08) == "- (the sweep fails on 1.5-6.0%)"
    assert mod.threshold_at(fails, thresholds, 0.01) == "- (the sweep fails on 1.5-6.0%)"
