"""A user's own metric (``rtp.metrics.Metric``): declared, looked up, computed, stored as targets,
trained for, exported and evaluated as rtp's own; the example plugin examples/metric_plugin (SSIM)."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator
from importlib.metadata import entry_points
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from rtp import metrics, sdk
from rtp.metrics import _plugins

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "metric_plugin"
RATES = sdk.PREDICTED_RATES


def example_module() -> ModuleType:
    """examples/metric_plugin/rtp_ssim.py, imported from its file."""
    spec = importlib.util.spec_from_file_location("rtp_ssim", EXAMPLE / "rtp_ssim.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def install_entry_points(folder: Path, entries: dict[str, str], modules: dict[str, str] | None = None,
                         dist: str = "rtp_user_metrics") -> Path:
    """A distribution's metadata with ``rtp.metrics`` entry points (and its modules) in ``folder``: on
    ``sys.path`` (or PYTHONPATH) it is what ``pip install`` of a package declaring them leaves."""
    info = folder / f"{dist}-1.0.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    lines = "".join(f"{name} = {value}\n" for name, value in entries.items())
    (info / "entry_points.txt").write_text(f"[{metrics.METRIC_ENTRY_POINT_GROUP}]\n{lines}")
    for name, text in (modules or {}).items():
        (folder / f"{name}.py").write_text(textwrap.dedent(text))
    return folder


@pytest.fixture
def registry(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The plugin registry as this test leaves it is not the next test's: empty, rediscovered, restored."""
    monkeypatch.setattr(_plugins, "_registered", {})
    monkeypatch.setattr(_plugins, "_broken", {})
    monkeypatch.setattr(_plugins, "_explicit", set())
    _plugins._entry_points.cache_clear()
    yield
    _plugins._entry_points.cache_clear()


def absdiff(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    return np.abs(reference - test).mean(axis=-1)


def frames(seed: int = 0, h: int = 37, w: int = 53) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    ref = rng.random((h, w, 3), dtype=np.float32)
    return ref, {r: np.clip(ref + rng.normal(0, 0.05 * (i + 1), ref.shape), 0, 1).astype(np.float32)
                 for i, r in enumerate(RATES)}


# -- the Metric --------------------------------------------------------------------------------------

@pytest.mark.parametrize("kw", [
    {"name": "SSIM"}, {"name": "1x"}, {"name": "a-b"}, {"name": "x" * 65}, {"name": "flip"}, {"name": "jnssim"},
    {"name": 3}, {"error_map": "absdiff"}, {"default_threshold": 0}, {"default_threshold": float("nan")},
    {"default_threshold": True}, {"default_threshold": "0.1"}, {"default_threshold": 10**400},  # (was OverflowError)
    {"pooling": "min"}, {"pooling": "mse"},
    {"units": 1}, {"description": None}, {"params": {"a": object()}}, {"params": {"a": float("inf")}},
    {"params": {1: 2}}, {"params": [1]}, {"requires": "scipy"}, {"requires": ("",)},
    {"requires": None}, {"requires": 3}, {"requires": {"scipy": 1}},  # (None and 3 were TypeErrors: the fuzzer's)
])
def test_a_metric_that_cannot_work_is_refused_when_declared(kw: dict[str, Any]) -> None:
    args = {"name": "mine", "error_map": absdiff, "default_threshold": 0.1, **kw}
    with pytest.raises(metrics.MetricParameterError) as exc:
        metrics.Metric(**args)
    assert str(exc.value).startswith("Metric")


def test_a_metric_states_its_facts_as_rtps_own() -> None:
    m = metrics.Metric("mine", absdiff, 0.05, pooling="mean", units="abs", params={"v": 2}, requires=["numpy"])
    assert m.info == sdk.MetricInfo("mine", False, "abs", (0.0, np.inf), "mean", False,
                                    "mine (a plugin metric), mean over the tile", 0.05)
    assert m.requires == ("numpy",) and dict(m.params) == {"v": 2}
    with pytest.raises(TypeError):
        m.params["v"] = 3  # type: ignore[index]  # (recorded with targets: not to change under them)


def test_registered_metrics_are_known_and_looked_up(registry: None) -> None:
    before = metrics.known_metrics()  # (rtp's own, then any plugin this environment has installed)
    assert before[:len(sdk.METRICS)] == tuple(sdk.METRICS) and "absdiff" not in before
    with pytest.raises(metrics.MetricParameterError, match="unknown metric 'absdif'; metrics are"):
        metrics.metric_info("absdif")
    m = metrics.Metric("absdiff", absdiff, 0.05)
    metrics.register_metric(m)
    assert metrics.known_metrics() == (*sdk.METRICS, *sorted([*before[len(sdk.METRICS):], "absdiff"]))
    assert metrics.metric_info("absdiff") == m.info and metrics.metric_info("flip") is sdk.METRICS["flip"]
    with pytest.raises(metrics.MetricParameterError, match=r"'absdif' \(did you mean absdiff\?\)"):
        metrics.metric_info("absdif")
    for bad in (None, 3, ["flip"]):
        with pytest.raises(metrics.MetricParameterError):
            metrics.metric_info(bad)  # type: ignore[arg-type]
    with pytest.raises(metrics.MetricParameterError, match="takes an rtp.metrics.Metric"):
        metrics.register_metric(m.info)  # type: ignore[arg-type]


# -- computing it -----------------------------------------------------------------------------------

@pytest.mark.parametrize("pooling", ["max", "mean"])
def test_plugin_targets_pool_its_map_and_leave_rtps_own_alone(registry: None, pooling: str) -> None:
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05, pooling=pooling))
    ref, images = frames()
    got = metrics.tile_targets(ref, images, ("absdiff", "jnyang", "psnr"), 8)
    alone = metrics.tile_targets(ref, images, ("jnyang", "psnr"), 8)
    for m in ("jnyang", "psnr"):
        np.testing.assert_array_equal(got[m], alone[m])
    for i, r in enumerate(RATES):
        d = absdiff(ref, images[r])
        want = np.array([[getattr(np, pooling)(d[y:y + 8, x:x + 8]) for x in range(0, 53, 8)] for y in range(0, 37, 8)])
        np.testing.assert_allclose(got["absdiff"][i], want, rtol=1e-6)
        np.testing.assert_array_equal(metrics.tile_metric("absdiff", ref, images[r], 8), got["absdiff"][i])
    np.testing.assert_array_equal(metrics.error_map("absdiff", ref, images["2x2"]), absdiff(ref, images["2x2"]))


class _Unconvertible:
    """What a learned metric's map gives as a torch tensor that requires grad: ``np.asarray`` raises RuntimeError."""

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        raise RuntimeError("Can't call numpy() on Tensor that requires grad. Use tensor.detach().numpy() instead.")


@pytest.mark.parametrize("result, match", [
    (lambda r, t: np.zeros(r.shape[:2] + (1,)), r"returned float64 \(37, 53, 1\)"),
    (lambda r, t: np.zeros(5), r"returned float64 \(5,\)"),
    (lambda r, t: np.full(r.shape[:2], np.nan), r"outside \[0, inf\) \(1961 NaN of 1961 pixels\)"),
    (lambda r, t: -np.ones(r.shape[:2]), r"outside \[0, inf\) \(1961 negative of 1961 pixels, down to -1\)"),
    # (these three were taken: targets of the similarity, the offset, the noise, which no threshold reads right)
    (lambda r, t: np.exp(-np.abs(r - t).mean(axis=-1)), "of a frame against itself gives up to 1 .*not 0"),
    (lambda r, t: np.abs(r - t).mean(axis=-1) + 0.002, "of a frame against itself gives up to 0.002 "),
    (lambda r, t: np.abs(r - t).mean(axis=-1) + np.random.default_rng().uniform(0.01, 0.02, r.shape[:2]),
     "against itself.*the same map for the same frames"),
    (lambda r, t: np.full(r.shape[:2], 1e300), "up to 1e\\+300, beyond float32's range"),  # (was "NaN, infinite")
    (lambda r, t: "map", "dtype|returned"),
    (lambda r, t: _Unconvertible(), r"returned _Unconvertible, not an array \(RuntimeError: Can't call numpy"),
    (lambda r, t: 1 / 0, "error_map failed on 53x37 frames: ZeroDivisionError"),
    (lambda r, t: r.__setitem__(0, 0.0), "failed.*read-only"),  # (writing into the shared reference)
    (lambda r, t: sys.exit(3), "failed on 53x37 frames: SystemExit: 3"),  # (it ended rtp silently, exit 3)
])
def test_a_broken_map_is_the_plugins_error_not_wrong_targets(registry: None, result: Any, match: str) -> None:
    metrics.register_metric(metrics.Metric("bad", result, 0.1))
    ref, images = frames()
    before = ref.copy()
    with pytest.raises(metrics.MetricError, match=f"the metric 'bad'.*({match})"):
        metrics.tile_targets(ref, images, ("jnyang", "bad"), 16)
    np.testing.assert_array_equal(ref, before)


def test_a_maps_round_off_below_zero_is_zero_and_equal_frames_are_checked_once(registry: None) -> None:
    # 1 - SSIM of equal pixels is -7.6e-12 and so on in float64: it was refused, "NaN, infinite or negative"
    calls: list[bool] = []

    def dissimilar(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
        calls.append(bool(np.array_equal(reference, test)))
        return np.abs(reference - test).mean(axis=-1) - 1e-12

    metrics.register_metric(metrics.Metric("dssim", dissimilar, 0.1))
    ref, images = frames()
    got = metrics.tile_targets(ref, images, ("dssim",), 8)
    assert got["dssim"].dtype == np.float32 and (got["dssim"] >= 0).all()
    assert calls == [False, True, *[False] * 5]  # (the frame against itself once in a process, not every sample)
    for i, r in enumerate(RATES):
        want = np.maximum(np.abs(ref - images[r]).mean(axis=-1) - 1e-12, 0)
        np.testing.assert_allclose(got["dssim"][i], metrics.pool_tiles(want, 8), rtol=1e-6)
    np.testing.assert_array_equal(metrics.error_map("dssim", ref, ref), np.zeros(ref.shape[:2], np.float32))
    # a map of equal frames up to 1% of the threshold is taken (a floor of round-off), as it is
    metrics.register_metric(metrics.Metric("floor", lambda r, t: np.abs(r - t).mean(axis=-1) + 0.0009, 0.1))
    np.testing.assert_allclose(metrics.error_map("floor", ref, ref), 0.0009, rtol=1e-6)


def test_plugin_maps_take_one_numpy_frame_of_the_tests_size(registry: None) -> None:
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05))
    ref, images = frames()
    with pytest.raises(sdk.InputShapeError, match="reference's"):
        metrics.error_map("absdiff", ref, images["1x2"][:-1])
    with pytest.raises(sdk.InputShapeError, match="one numpy"):
        metrics.error_map("absdiff", np.stack([ref, ref]), np.stack([ref, ref]))
    with pytest.raises(metrics.InputRangeError):
        metrics.error_map("absdiff", ref * 2, ref)


def test_dependencies_of_a_plugin_are_checked_before_a_job(registry: None, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    metrics.register_metric(metrics.Metric("needy", absdiff, 0.1, requires=("rtp_no_such_module_xyz",)))
    metrics.register_metric(metrics.Metric("ready", absdiff, 0.1, requires=("numpy",)))
    metrics.check_dependencies(["ready", "psnr"])
    with pytest.raises(metrics.MetricDependencyError, match="'needy' needs rtp_no_such_module_xyz: pip install "
                                                            "rtp_no_such_module_xyz"):
        metrics.check_dependencies(["psnr", "needy"])
    # rtp metric too (it blamed the plugin's error_map: "error_map failed on 64x48 frames: ModuleNotFoundError")
    from rtp.capture import save_image
    from rtp.cli import main

    ref, images = frames()
    save_image(tmp_path / "a.png", ref)
    save_image(tmp_path / "b.png", images["2x2"])
    assert main(["metric", "needy", str(tmp_path / "a.png"), str(tmp_path / "b.png")]) == 2
    assert capsys.readouterr().err == ("rtp metric: error: missing before any work starts: the metric 'needy' needs "
                                       "rtp_no_such_module_xyz: pip install "
                                       "rtp_no_such_module_xyz\n")


# -- entry points -----------------------------------------------------------------------------------

def test_entry_points_declare_metrics_and_a_broken_one_spares_the_others(
        registry: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    install_entry_points(tmp_path, {
        "good": "rtp_good_metric:GOOD", "broken": "rtp_broken_metric:X", "notmetric": "rtp_good_metric:absdiff",
        "renamed": "rtp_good_metric:GOOD"}, {
        "rtp_good_metric": """
            import numpy as np
            from rtp.metrics import Metric
            def absdiff(r, t):
                return np.abs(r - t).max(axis=-1)
            GOOD = Metric("good", absdiff, 0.2, pooling="max", units="abs")
            """,
        "rtp_broken_metric": "raise ImportError('no module named torchmetrics')\n"})
    monkeypatch.syspath_prepend(str(tmp_path))
    assert metrics.metric_info("good").units == "abs"
    with pytest.raises(metrics.MetricParameterError, match=r"'broken' is installed but failed to load \(ImportError: "
                                                           r"no module named torchmetrics\).*rtp_broken_metric:X"):
        metrics.metric_info("broken")
    with pytest.raises(metrics.MetricParameterError, match="'notmetric' is installed but is function, not an rtp"):
        metrics.metric_info("notmetric")
    with pytest.raises(metrics.MetricParameterError, match="'renamed' is installed but is the Metric 'good'"):
        metrics.metric_info("renamed")
    with caplog.at_level("WARNING", "rtp.metrics"):
        known = metrics.known_metrics()
    assert "good" in known and not {"broken", "notmetric", "renamed"} & set(known)
    ref, images = frames()
    assert metrics.tile_targets(ref, images, ("good",), 16)["good"].shape == (6, 3, 4)


def test_entry_points_of_rtps_own_names_are_ignored_and_each_broken_one_is_named(
        registry: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """An entry point `psnr = pkg:MSE` was imported and reported as "is the Metric 'mse': an entry point's name is
    its metric's"; and the command's log showed the first broken plugin's warning only ("1 more like")."""
    from rtp.cli import main

    install_entry_points(tmp_path, {"psnr": "rtp_own_name_metric:X", "jnssim": "rtp_own_name_metric:X",
                                    "broken_a": "rtp_broken_a:X", "broken_b": "rtp_broken_b:X"},
                         {"rtp_own_name_metric": "raise RuntimeError('imported')\n",
                          "rtp_broken_a": "raise ImportError('needs torchmetrics')\n",
                          "rtp_broken_b": "raise ImportError('needs kornia')\n"})
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["weights", "list"]) == 0
    err = capsys.readouterr().err
    assert "'broken_a' (rtp_broken_a:X) failed to load (ImportError: needs torchmetrics)" in err, err
    assert "'broken_b' (rtp_broken_b:X) failed to load (ImportError: needs kornia)" in err, err
    for name in ("psnr", "jnssim"):
        assert f"metric plugin {name!r} (rtp_own_name_metric:X) is ignored: rtp's own metrics" in err, err
    assert "imported" not in err and "more like" not in err, err
    assert metrics.metric_info("psnr") is sdk.METRICS["psnr"]


def test_a_registered_metric_wins_over_an_entry_point(registry: None, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    install_entry_points(tmp_path, {"ssim": "rtp_ssim:SSIM"})
    monkeypatch.syspath_prepend(str(EXAMPLE))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert metrics.metric_info("ssim").units == "DSSIM"
    metrics.register_metric(metrics.Metric("ssim", absdiff, 0.5, units="mine"))
    assert metrics.metric_info("ssim").units == "mine"


# -- the example: SSIM --------------------------------------------------------------------------------

def test_example_ssim_is_wang_et_al_windowed_ssim() -> None:
    mod = example_module()
    ref, images = frames(3, 24, 31)
    test = images["4x4"]
    s = mod.ssim_map(ref, test)
    assert s.shape == (24, 31)
    np.testing.assert_allclose(mod.ssim_map(ref, ref), 1.0, atol=1e-12)
    assert np.all(mod.dssim_map(ref, ref) == 0)
    # brute force at some pixels: the 11x11 window of a Gaussian of sigma 1.5 over the mirrored luma
    x, y = (np.pad(sdk.luma(f).astype(np.float64), 5, mode="symmetric") for f in (ref, test))
    g = np.exp(-0.5 * (np.arange(-5, 6) / 1.5) ** 2)
    win = np.outer(g, g) / np.outer(g, g).sum()
    for i, j in [(0, 0), (7, 12), (23, 30), (12, 0)]:
        a, b = x[i:i + 11, j:j + 11], y[i:i + 11, j:j + 11]
        ma, mb = (win * a).sum(), (win * b).sum()
        va, vb, cov = (win * a * a).sum() - ma**2, (win * b * b).sum() - mb**2, (win * a * b).sum() - ma * mb
        want = (2 * ma * mb + 1e-4) * (2 * cov + 9e-4) / ((ma**2 + mb**2 + 1e-4) * (va + vb + 9e-4))
        assert s[i, j] == pytest.approx(want, abs=1e-12)
    d = mod.dssim_map(ref, test)
    assert d.dtype == np.float32 and 0 < d.mean() < 1
    assert mod.SSIM.name == "ssim" and mod.SSIM.pooling == "mean" and mod.SSIM.error_map is mod.dssim_map


def _env(*paths: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*map(str, paths), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def test_example_package_declares_the_entry_point_pip_installs() -> None:
    import tomllib

    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())
    assert project["project"]["entry-points"][metrics.METRIC_ENTRY_POINT_GROUP] == {"ssim": "rtp_ssim:SSIM"}
    assert project["tool"]["setuptools"]["py-modules"] == ["rtp_ssim"]


@pytest.mark.gl
@pytest.mark.slow
def test_a_plugin_metric_through_every_job(tmp_path: Path) -> None:
    """Installed as a package would be (entry point in a distribution's metadata, found on PYTHONPATH by
    fresh processes): the targets (in two worker processes), a model trained and exported for it, loaded,
    evaluated, and the metric command; then the definition changed under the stored targets is refused."""
    from rtp.capture import capture

    data = tmp_path / "ds"
    capture(["procedural:11", "procedural:12"], data, per_scene=2, size=(128, 96))
    # the example installed as its page says, by pip (into a folder, from a copy: a build leaves files beside it)
    shutil.copytree(EXAMPLE, tmp_path / "example")
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--target",
                    str(site), str(tmp_path / "example")], check=True, capture_output=True, timeout=300)
    env = _env(site)

    def rtp(*argv: str, ok: bool = True) -> subprocess.CompletedProcess[str]:
        r = subprocess.run([sys.executable, "-m", "rtp.cli", "--no-progress", *argv], capture_output=True, text=True,
                           env=env, cwd=tmp_path, timeout=600)
        assert (r.returncode == 0) == ok, (argv, r.stdout, r.stderr)
        return r

    listed = rtp("weights", "list").stdout
    assert any(line.split()[:2] == ["ssim", "-"] and "ready (plugin: rtp_ssim)" in line for line in listed.splitlines())
    rtp("targets", str(data), "--metrics", "ssim,jnyang", "--workers", "2")
    manifest = json.loads((data / "targets" / "manifest.json").read_text())
    assert manifest["metrics"]["ssim"] == {"plugin": {"version": 1, "window": 11, "sigma": 1.5}, "pooling": "mean"}

    from rtp.capture import DatasetReader, TargetStore

    mod = example_module()
    reader, store = DatasetReader(data), TargetStore(data)
    sample = reader[reader.ids[0]]
    ref = sample.final("1x1")
    for i, r in enumerate(RATES):  # stored at 4 px, read at 16: the pixel-weighted mean of the means
        want = np.array([[mod.dssim_map(ref, sample.final(r))[y:y + 16, x:x + 16].mean() for x in range(0, 128, 16)]
                         for y in range(0, 96, 16)])
        np.testing.assert_allclose(store.load(reader.ids[0], "ssim", 16)[i], want, rtol=1e-5, atol=1e-7)

    rtp("train", "--data", str(data), "--metric", "ssim", "--out", "ssim.pt", "--steps", "30", "--batch", "4",
        "--crop", "64", "--val-scenes", "procedural:12")
    r = subprocess.run([sys.executable, "-m", "rtp.cli.export", "ssim.pt", "-o", "ssim.onnx"], capture_output=True,
                       text=True, env=env, cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr
    pred = sdk.load(tmp_path / "ssim.onnx")  # (a model of a metric rtp does not know: its metadata says enough)
    meta = pred.metadata
    assert (meta.metric, meta.higher_is_better, meta.default_threshold) == ("ssim", False, 0.03)
    assert pred.shading_rates(sample.inputs(meta.inputs)).shape == (6, 8)
    info = rtp("info", "ssim.onnx").stdout
    assert "ssim (lower is better)" in info
    rtp("evaluate", "ssim.onnx", "--data", str(data), "--out", "ev")
    (report,) = json.loads((tmp_path / "ev" / "evaluation.json").read_text())
    assert report["model"]["metric"] == "ssim" and report["model"]["higher_is_better"] is False

    # the demo computes its true error with the plugin, and play judges every method by it
    demo = rtp("demo", "--model", "ssim.onnx", "--size", "160x96", "--frames", "2", "--out", "demo").stdout
    assert "ssim" in demo and (tmp_path / "demo" / "predicted_vs_true.png").is_file()
    rtp("play", "procedural:0", "--methods", "ssim.onnx,oracle,full", "--path", "fast", "--frames", "3", "--size",
        "160x96", "--fail-metric", "ssim", "--no-sweep", "--flip-every", "0", "--no-plots", "--no-animation",
        "--out", "play")
    played = json.loads((tmp_path / "play" / "play.json").read_text())
    assert played["settings"]["fail_metric"] == "ssim" and played["settings"]["fail_threshold"] == 0.03

    from PIL import Image

    for name, img in (("a.png", ref), ("b.png", sample.final("4x4"))):
        Image.fromarray((img * 255).round().astype(np.uint8)).save(tmp_path / name)
    tiles = json.loads(rtp("metric", "ssim", "a.png", "b.png", "--json").stdout)
    assert tiles["metric"] == "ssim" and tiles["units"] == "DSSIM" and len(tiles["tiles"]) == 6

    # another definition of the metric under the same name: its stored targets are not mixed with new ones
    changed = tmp_path / "changed"
    changed.mkdir()
    (changed / "rtp_ssim.py").write_text((EXAMPLE / "rtp_ssim.py").read_text().replace('"version": 1', '"version": 2'))
    env = _env(changed, site)
    refused = rtp("targets", str(data), "--metrics", "ssim", ok=False)
    assert "targets for ssim" in refused.stderr and "were computed with" in refused.stderr
    # without the plugin installed (as in CI: not where a developer pip-installed the example), the name is
    # unknown and says where metrics come from
    if "ssim" not in {ep.name for ep in entry_points(group=metrics.METRIC_ENTRY_POINT_GROUP)}:
        env = _env()
        missing = rtp("train", "--data", str(data), "--metric", "ssim", "--out", "x.pt", ok=False)
        assert "unknown metric 'ssim'" in missing.stderr and "rtp.metrics" in missing.stderr


def test_a_metric_registered_in_this_process_is_refused_where_workers_would_compute_it(
        registry: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rtp.capture import TargetError, compute_targets
    from rtp.evaluate import PlayError, play

    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05))
    for kw in ({"workers": 2}, {"ray": "local"}):
        with pytest.raises(TargetError, match="'absdiff' is registered in this process only.*entry-point group"):
            compute_targets(tmp_path / "none", ("jnyang", "absdiff"), **kw)  # type: ignore[arg-type]
    with pytest.raises(PlayError, match="'absdiff' is registered in this process only"):
        play("procedural:0", "full", paths=["slow", "fast"], frames=3, workers=2, fail_metric="absdiff",
             out=tmp_path / "play")
    # declared as an entry point too, the workers find it
    install_entry_points(tmp_path / "site", {"absdiff": "rtp_absdiff_metric:M"},
                         {"rtp_absdiff_metric": "import numpy as np\nfrom rtp.metrics import Metric\n"
                                                "M = Metric('absdiff', lambda r, t: np.abs(r - t).mean(-1), 0.05)\n"})
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    _plugins._entry_points.cache_clear()
    metrics.check_worker_metrics(["absdiff", "flip"])


@pytest.mark.gl
def test_a_play_failing_on_its_metric_leaves_no_empty_folder(registry: None, tmp_path: Path) -> None:
    """A fail metric whose map raises stopped rtp play with an error and an empty --out folder it had made;
    a folder that was there before stays."""
    from rtp.evaluate import play

    def broken(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
        raise RuntimeError("out of licences")

    metrics.register_metric(metrics.Metric("broken", broken, 0.05))
    for out, kept in ((tmp_path / "new" / "play", False), (tmp_path, True)):
        with pytest.raises(metrics.MetricError, match="'broken'.*out of licences"):
            play("procedural:0", "full", paths=["fast"], frames=3, size=(64, 48), fail_metric="broken", out=out,
                 sweep=False)
        assert out.is_dir() == kept
    assert (tmp_path / "new").is_dir()  # (the parents it made, which it cannot tell from a user's, stay)


@pytest.mark.gl
def test_stored_targets_of_a_max_pooled_plugin_coarsen_by_their_maximum(registry: None, tmp_path: Path) -> None:
    from rtp.capture import DatasetReader, TargetStore, capture, compute_targets

    data = tmp_path / "ds"
    capture(["procedural:3"], data, per_scene=1, size=(72, 40))
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05))  # (in this process: one worker)
    assert compute_targets(data, ("absdiff",), workers=1) == 2  # (one viewpoint of each motion profile)
    reader, store = DatasetReader(data), TargetStore(data)
    for sample_id in reader.ids:
        sample = reader[sample_id]
        ref = sample.final("1x1")
        got = store.load(sample_id, "absdiff", 16)
        for i, r in enumerate(RATES):
            np.testing.assert_array_equal(got[i], metrics.tile_metric("absdiff", ref, sample.final(r), 16))
    assert store.metrics["absdiff"] == {"plugin": {}, "pooling": "max"}


def test_a_metric_registered_over_its_entry_point_is_refused_where_workers_compute_the_entry_points(
        registry: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Registered in this process under an installed entry point's name with another definition (params
    {"version": 2}), a targets job with workers declared the registered metric's params in the manifest while its
    workers computed the entry point's (version 1): two definitions under one name, in silence. The entry point's
    own metric registered again (or one of its params and pooling: its definition) is taken."""
    from rtp.capture import TargetError, compute_targets

    install_entry_points(tmp_path / "site", {"absdiff": "rtp_absdiff_v1:M"},
                         {"rtp_absdiff_v1": "import numpy as np\nfrom rtp.metrics import Metric\n"
                                            "M = Metric('absdiff', lambda r, t: np.abs(r - t).mean(-1), 0.05, "
                                            "params={'version': 1})\n"})
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    _plugins._entry_points.cache_clear()
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05, params={"version": 2}))
    for kw in ({"workers": 2}, {"ray": "local"}):
        with pytest.raises(TargetError, match=r"'absdiff' registered in this process \(rtp.metrics.register_metric\) "
                                              r"defines it by \{'params': \{'version': 2\}, 'pooling': 'max'\}, its "
                                              r"entry point 'rtp_absdiff_v1:M', which worker processes compute, by "
                                              r"\{'params': \{'version': 1\}"):
            compute_targets(tmp_path / "none", ("jnyang", "absdiff"), **kw)  # type: ignore[arg-type]
    import rtp_absdiff_v1  # type: ignore[import-not-found]

    metrics.register_metric(rtp_absdiff_v1.M)
    metrics.check_worker_metrics(["absdiff", "flip"])


def test_a_model_of_one_plugin_definition_judged_on_anothers_targets_is_said(
        registry: None, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A model trained on a plugin metric's version-1 targets (its provenance.target_parameters) was evaluated
    against a dataset whose targets the plugin's version 2 computed, and scored in silence; the run now warns and
    the report's first note says so. Evaluating needs no plugin: the definitions are the recorded ones."""
    from rtp.capture import DatasetWriter, TargetStore
    from rtp.evaluate import evaluate

    from .conftest import base_metadata, build_onnx

    h, w = 32, 48
    data = tmp_path / "data"
    writer, store = DatasetWriter(data), TargetStore(data)
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05, params={"version": 2}))  # (to declare)
    store.declare("absdiff", {"plugin": {"version": 2}, "pooling": "max"})
    _random_samples(writer, store, 2, (h, w), lambda i: "a")
    _plugins._registered.clear()  # (not installed where the model is evaluated)

    def model(version: int) -> Path:
        meta = base_metadata(metric="absdiff", higher_is_better=False, weber_l=None, default_threshold=0.05,
                             transform={"type": "clamped", "mu_y": 0.05},
                             provenance={"target_parameters": {"plugin": {"version": version}, "pooling": "max"}})
        return build_onnx(tmp_path / f"v{version}.onnx", weights=np.zeros((4, 4), np.float32), metadata=meta)

    words = ("the model predicts the plugin metric absdiff as defined by {'plugin': {'version': 1}, 'pooling': 'max'}, "
             "and the targets it is judged against were computed with {'plugin': {'version': 2}, 'pooling': 'max'}")
    with caplog.at_level("WARNING", logger="rtp.evaluate"):
        rep = evaluate(model(1), data, baselines=False, sweep=False)
    assert rep.notes[0].startswith(words) and words in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="rtp.evaluate"):
        rep = evaluate(model(2), data, baselines=False, sweep=False)
    assert "definition" not in caplog.text and not any("another definition" in n for n in rep.notes)


def _random_samples(writer: Any, store: Any, n: int, size: tuple[int, int], scene: Callable[[int], str]) -> None:
    """``n`` samples s0, s1, ... of random buffers of ``size`` (H, W) in ``scene(i)``, each with random absdiff
    targets, written and the dataset finalised."""
    from rtp.capture import BUFFERS

    h, w = size
    rng = np.random.default_rng(0)
    for i in range(n):
        writer.write(f"s{i}", {name: rng.random((h, w, len(spec.channels) or 3) if len(spec.channels) != 1
                                                else (h, w), dtype=np.float32) for name, spec in BUFFERS.items()},
                     {"scene": scene(i)})
        store.write(f"s{i}", "absdiff", rng.uniform(0, 0.1, (6, h // 4, w // 4)).astype(np.float32), (h, w))
    writer.finalize()


def test_training_on_another_plugin_definitions_targets_warns_of_the_installed_threshold(
        registry: None, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Targets computed by a plugin metric's version 1, version 2 installed at training (its default threshold 5.0,
    in other units): the model learns the stored targets and records their definition, and took the installed
    plugin's threshold in silence. It still takes it (the stored definition records none), and warns, naming both
    definitions and ``--threshold``; not where the definitions agree, nor with a threshold given."""
    from rtp.capture import DatasetWriter, TargetStore
    from rtp.train import TrainConfig, train
    from rtp.train.checkpoint import load as load_checkpoint

    h, w = 64, 96
    data = tmp_path / "data"
    writer, store = DatasetWriter(data), TargetStore(data)
    metrics.register_metric(metrics.Metric("absdiff", absdiff, 0.05, params={"version": 1}))  # (to declare)
    store.declare("absdiff", {"plugin": {"version": 1}, "pooling": "max"})
    _random_samples(writer, store, 6, (h, w), lambda i: f"scene{i % 3}")
    cfg = dict(data=str(data), metric="absdiff", steps=2, crop=32, batch=4, val_every=2, save_every=2, arch="fast",
               val_scenes=("scene0",))
    words = (f"the absdiff targets of {data} were computed by another definition of the plugin metric ({{'plugin': "
             "{'version': 1}, 'pooling': 'max'}) than the one installed ({'plugin': {'version': 2}, 'pooling': "
             "'max'}): the model learns them and records their definition, but takes its default_threshold, 5, from "
             "the installed plugin")
    for version, given, warned in ((2, None, True), (2, 0.05, False), (1, None, False)):
        _plugins._registered.clear()
        metrics.register_metric(metrics.Metric("absdiff", absdiff, 5.0, params={"version": version}))
        out = tmp_path / f"v{version}-{given}.pt"
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp.train"):
            train(TrainConfig(out=str(out), default_threshold=given, **cfg))  # type: ignore[arg-type]
        assert (words in caplog.text) == warned, caplog.text
        if warned:
            assert "rtp train --threshold" in caplog.text
        meta = load_checkpoint(out).metadata
        assert meta.default_threshold == (5.0 if given is None else given)
        assert meta.to_dict()["provenance"]["target_parameters"] == {"plugin": {"version": 1}, "pooling": "max"}


@pytest.mark.gl
def test_a_targets_job_refused_by_a_plugins_map_names_the_sample(registry: None, tmp_path: Path) -> None:
    """A plugin's map refused in a targets job said what the map gave, not on which sample (only -v's traceback
    did): the sample is named, to look at it."""
    from rtp.capture import DatasetReader, capture, compute_targets

    data = tmp_path / "ds"
    capture(["procedural:3"], data, per_scene=1, size=(72, 40))
    metrics.register_metric(metrics.Metric("nans", lambda a, b: np.full(a.shape[:2], np.nan), 0.05))
    first = DatasetReader(data).ids[0]
    with pytest.raises(metrics.MetricError, match=rf"^sample {first!r}: the metric 'nans''s error_map returned "
                                                  r"values outside \[0, inf\) \(2880 NaN of 2880 pixels\)"):
        compute_targets(data, ("nans",), workers=1)
