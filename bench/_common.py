"""Helpers shared by the benchmark scripts (run them as `python bench/<name>.py`).

Every script ends in ``run_main(main)``: an rtp error (a model, map or dataset that is not there, a
bad value found by the library) prints one line, ``NAME.py: error: ...``, with rtp's exit code
(docs/errors.md), as the ``rtp`` commands do; ``RTP_TRACEBACK=1`` shows the traceback above it. The
argparse types below (:func:`positive`, :func:`positives`, :func:`count`, :func:`frame_size`, :func:`frame_sizes`,
:func:`dataset_folder`, :func:`json_file`, :func:`number`) refuse bad arguments before any work, as
:func:`check_targets` refuses a dataset without the targets a script reads.
"""

from __future__ import annotations

import shlex
import statistics
import time
from collections.abc import Callable, Hashable, Sequence
from pathlib import Path
from typing import Any, NoReturn, TypeVar

from rtp.sdk import EXIT_USAGE, RtpError

K = TypeVar("K", bound=Hashable)


def cpu_description() -> str:
    """The CPU for a benchmark's header: its model name and its widest vector unit (AVX-512, AVX2, or
    what the platform module says where /proc/cpuinfo is not there). onnxruntime's blocked convolutions
    depend on it: an eight-plane first layer ran twice as slowly on an AVX2-only CPU before rtp-export
    split the planes (docs/performance.md "Input planes on AVX2 CPUs")."""
    import platform

    try:
        info = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return platform.processor() or platform.machine()
    fields = dict(line.split(":", 1) for line in info.splitlines() if ":" in line)
    fields = {k.strip(): v.strip() for k, v in fields.items()}
    flags = set(fields.get("flags", "").split())
    vector = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2"
    return f"{fields.get('model name', platform.machine())} ({vector}, {platform.machine()})"


def scene_ids(reader: Any, scenes: str | None) -> list[str]:
    """The sample ids of ``reader`` (a ``rtp.capture.DatasetReader``) whose map is one of ``scenes``
    (comma-separated; None or empty: every sample). Empty when none matches."""
    ids = list(reader.ids)
    wanted = {n.strip() for n in (scenes or "").split(",") if n.strip()}
    return [i for i in ids if reader[i].meta.get("scene") in wanted] if wanted else ids


def check_targets(store: Any, ids: Sequence[str], metric: str, tile: int, model: str = "") -> None:
    """Refuse, before a script prints or reads a sample, a dataset (``store``: its ``rtp.capture.TargetStore``)
    without ``metric``'s targets for every one of ``ids`` at a tile size they pool to (``tile``): a
    :class:`UsageError` that names the command computing them, instead of a table header and then the
    first missing file."""
    data = store.root.parent
    reads = f" for {model}" if model else ""
    if metric not in store.metrics:
        raise UsageError(f"{data} has no {metric} targets{reads} (it has {', '.join(store.metrics) or 'none'}): "
                         f"run `rtp targets {shlex.quote(str(data))} --metrics {metric}`")
    if tile % store.base_tile:
        raise UsageError(f"{data}: {model or 'the model'}'s {tile}-pixel tiles are not a multiple of its targets' "
                         f"base tile {store.base_tile}")
    missing = [i for i in ids if not store.path(i, metric).is_file()]
    if missing:
        raise UsageError(f"{data} has {metric} targets{reads} on {len(ids) - len(missing)} of the {len(ids)} samples "
                         f"read (none on {missing[0]}): run `rtp targets {shlex.quote(str(data))} --metrics {metric}`")


def dataset_folder(text: str) -> str:
    """An argparse type: a dataset folder ``rtp capture`` wrote (its ``manifest.json``), else a usage
    error that says how to make one, instead of a traceback once the script has loaded its model."""
    import argparse

    if not (Path(text) / "manifest.json").is_file():
        raise argparse.ArgumentTypeError(
            f"no dataset at {text!r}: capture one first, e.g. `rtp capture --split validation --per-scene 12 "
            f"--size 1280x720 --out {shlex.quote(text)} && rtp targets {shlex.quote(text)}` (the validation maps), or "
            "`make dataset` (data/train and data/test: about 3 hours)")
    from rtp.capture import open_dataset
    from rtp.sdk import RtpError

    try:  # a manifest.json of something else, or of a newer format
        open_dataset(text)
    except RtpError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


class UsageError(RtpError):
    """What a benchmark refuses in its own words (a dataset without the maps asked for, runs without the
    method named): :func:`run_main` prints it in one line and exits 2."""

    exit_code = EXIT_USAGE


#: What installs each optional module a script imports when it starts (pyproject.toml's extras): torch and onnx with
#: training and export, tqdm (the progress bars) with the capture and evaluation tools.
EXTRAS = {"torch": "rtp[train]", "onnx": "rtp[export]", "tqdm": "rtp[capture]"}


def missing_extra(err: ImportError) -> NoReturn:
    """For a script's imports of optional modules (``try: import torch`` ... ``except ImportError as err:
    missing_extra(err)``): one line, ``NAME.py: error: ...`` naming the install command, and exit 2 (a missing
    install, docs/errors.md), where ``python bench/NAME.py --help`` without the extra was a traceback. An import
    that fails for another reason is raised again."""
    import sys

    name = (err.name or "").partition(".")[0]
    if name not in EXTRAS:
        raise err
    print(f"{Path(sys.argv[0]).name}: error: this script needs {name}, which is not installed: "
          f"pip install '{EXTRAS[name]}'", file=sys.stderr)
    raise SystemExit(EXIT_USAGE)


def run_main(main: Callable[[], int | None]) -> None:
    """Run a script's ``main`` under rtp's error policy (module docstring) and exit with its code."""
    import os
    import sys

    from rtp.cli import run_guarded

    prog = Path(sys.argv[0]).name  # (as argparse names it in its usage errors)
    sys.exit(run_guarded(prog, main, verbose=os.environ.get("RTP_TRACEBACK", "") not in ("", "0")))


def positive(text: str) -> int:
    """An argparse type: an integer >= 1 (repeats, threads, frames, samples, workers, steps)."""
    from rtp.cli import int_at_least

    return int_at_least(1)(text)


def positives(text: str) -> list[int]:
    """An argparse type: comma-separated integers >= 1 (worker counts), each :func:`positive`."""
    return [positive(v.strip()) for v in text.split(",")]


def count(text: str) -> int:
    """An argparse type: an integer >= 0 (seeds, and counts where 0 means none or all, as the help says)."""
    from rtp.cli import int_at_least

    return int_at_least(0)(text)


def json_file(text: str) -> Any:
    """An argparse type: the parsed contents of a JSON file (a report ``rtp play`` or a benchmark wrote),
    or a usage error that names the file and what is wrong with it."""
    import argparse
    import json

    try:
        return json.loads(Path(text).read_text(encoding="utf-8"))
    except OSError as err:
        raise argparse.ArgumentTypeError(f"{text!r}: {err.strerror or err}") from None
    except ValueError as err:  # JSONDecodeError, UnicodeDecodeError
        raise argparse.ArgumentTypeError(f"{text!r} is not JSON ({err})") from None


def report_file(kind: str, keys: dict[str, type], made_by: str, *, many: bool = False,
                name: str | None = None) -> Callable[[str], Path]:
    """An argparse type: the path of a JSON report holding ``keys``, each of its type (a list: of objects; a list
    of such reports with ``many``), checked when parsed: a missing file, bad JSON or another JSON (its keys, or
    their kinds of value) is a usage error, not a traceback (or, for another JSON, an empty table) once the
    script runs. A folder holding the report as ``name`` (the ``--out`` folder of the command that wrote it) is
    read as that file."""
    import argparse

    def fits(d: Any) -> bool:
        return isinstance(d, dict) and all(
            isinstance(d.get(k), t) and (t is not list or all(isinstance(v, dict) for v in d[k]))
            for k, t in keys.items())

    def parse(text: str) -> Path:
        if name is not None and Path(text).is_dir():  # (the --out folder given: "'play': Is a directory" before)
            if not (Path(text) / name).is_file():
                raise argparse.ArgumentTypeError(f"{text!r} is a folder without {name} in it (expected {kind}, the file "
                                                 f"{made_by} writes, or a folder holding it)")
            text = str(Path(text) / name)
        data = json_file(text)
        items = data if many and isinstance(data, list) else [data]
        if not items or not all(fits(d) for d in items):
            raise argparse.ArgumentTypeError(f"{text!r} is not {kind} (the file {made_by} writes)")
        return Path(text)

    return parse


#: The ``play.json`` of ``rtp play --out DIR``.
PLAY_JSON = report_file("a play.json", {"settings": dict, "rows": list}, "`rtp play --out DIR`", name="play.json")
#: The ``evaluation.json`` of ``rtp evaluate --out DIR`` (a list of reports, one per model).
EVALUATION_JSON = report_file("an evaluation.json", {"model": dict, "quality": list, "decisions": list},
                              "`rtp evaluate --out DIR`", many=True, name="evaluation.json")


def add_model_args(ap: Any, model_help: str, scene_help: str = "") -> None:
    """The arguments the model-on-a-dataset scripts share: ``model``, ``--data`` (default data/train) and
    ``--scene``, by default the maps of the ``validation`` split of scenes.yaml (the one list of them)."""
    from rtp.capture.scenes import map_names

    ap.add_argument("model", help=model_help)
    ap.add_argument("--data", type=dataset_folder, default="data/train", help="dataset with targets (default: data/train)")
    ap.add_argument("--scene", default=",".join(map_names("validation")),
                    help=f"maps of --data, comma-separated{scene_help} (default: the validation maps of scenes.yaml)")


def frame_size(text: str, minimum: int = 1) -> tuple[int, int]:
    """An argparse type: ``WIDTHxHEIGHT`` into ``(width, height)``, each at least ``minimum``."""
    import argparse

    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1920x1080, got {text!r}") from None
    if w < minimum or h < minimum:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT of at least {minimum}x{minimum}, got {text!r}")
    return w, h


def frame_sizes(minimum: int = 1) -> Callable[[str], list[tuple[int, int]]]:
    """An argparse type: comma-separated ``WIDTHxHEIGHT`` sizes (:func:`frame_size` each)."""
    def parse(text: str) -> list[tuple[int, int]]:
        return [frame_size(v, minimum) for v in text.split(",")]

    return parse


def number(low: float, high: float, *, above_low: bool = False, below_high: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number in ``[low, high]`` (``above_low``: ``(low, ...``; ``below_high``:
    ``..., high)``); NaN, infinities and what lies outside are usage errors, as the rtp commands' own."""
    import argparse
    import math

    interval = f"{'(' if above_low else '['}{low:g}, {high:g}{')' if below_high else ']'}"

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not ((low < v if above_low else low <= v) and (v < high if below_high else v <= high)):  # (NaN fails)
            raise argparse.ArgumentTypeError(f"expected a finite number in {interval}, got {text!r}")
        return v

    return parse


#: An argparse type: a share strictly between 0 and 1 (a failing share to fit or read at).
share = number(0, 1, above_low=True, below_high=True)


def median_ms(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn`` in milliseconds over ``repeats`` runs, after one warm-up run
    (first-call allocations, lazy construction, thread-pool start)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times)


def interleaved_ms(runs: dict[K, Callable[[], object]], rounds: int) -> dict[K, list[float]]:
    """Wall ms of every run in each of ``rounds`` rounds, after one warm-up round. A round runs each
    once, in turn, so a slow spell of the machine (these are shared 2-core VMs) falls on every model
    in the round instead of on the one being timed, and a ratio of two models' times within a round
    compares them under the same conditions."""
    for fn in runs.values():
        fn()
    out: dict[K, list[float]] = {key: [] for key in runs}
    for _ in range(rounds):
        for key, fn in runs.items():
            t0 = time.perf_counter()
            fn()
            out[key].append((time.perf_counter() - t0) * 1000)
    return out


#: The paper's configuration: 4 inputs, outputs 1x2/2x1/2x4/4x2, 16x16 tiles.
PAPER_METADATA = {
    "metric": "jnyang",
    "transform": {"type": "clamped", "mu_y": 0.25},
    "tile_size": 16,
    "inputs": ["reprojected.r", "seen", "albedo.r", "normal.z"],
    "outputs": ["1x2", "2x1", "2x4", "4x2"],
    "default_threshold": 0.25,
    "weber_l": 0.02,
}


#: Input sets by channel count for timing wider inputs: the paper's four, + normal x/y, and the ten
#: channels both adapters produce, and the paper's four + roughness, metallic, specular (bench/study.py's
#: "normals", "both-adapters" and "material").
TIMING_INPUTS = {
    4: tuple(PAPER_METADATA["inputs"]),
    6: ("reprojected.r", "seen", "albedo.r", "normal.x", "normal.y", "normal.z"),
    7: ("reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "metallic", "specular"),
    10: ("reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "albedo.g", "albedo.b",
         "normal.x", "normal.y", "normal.z"),
}


def paper_model(folder: Path, arch: str = "paper", inputs: int | Sequence[str] = 4,
                **config: Any) -> tuple[object, Path]:
    """The paper's network (or ``arch`` with ``config``: width, depth, stem, or any other option of
    ``rtp.train.model.build_network``) with random weights (cost does not depend on them) and the
    paper's outputs, on ``inputs`` channels (4: the paper's; 6, 7 or 10: :data:`TIMING_INPUTS`; or
    the channel names themselves, such as a shipped model's ``metadata.inputs``), exported with
    rtp-export into ``folder``: returns ``(torch network, onnx path)``. ``tile`` in ``config`` sets the
    tile size (default 16): the `-8px` models' blocks at 1/8 resolution cost what 16-pixel ones do not."""
    import torch

    from rtp.export import export_checkpoint
    from rtp.train import checkpoint
    from rtp.train.model import build_network

    if isinstance(inputs, int):
        if inputs not in TIMING_INPUTS:
            raise ValueError(f"inputs: expected one of {sorted(TIMING_INPUTS)} channels or a list of channel names, "
                             f"got {inputs}")
        names = list(TIMING_INPUTS[inputs])
    else:
        names = list(inputs)
    tile = config.pop("tile", PAPER_METADATA["tile_size"])
    torch.manual_seed(0)
    net = build_network(arch, len(names), 4, tile, **config).eval()
    # trained BatchNorm statistics are not the identity: random ones keep folding honest
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
            m.running_var.uniform_(0.5, 1.5)
    stem = f"{arch}-i{len(names)}-t{tile}-{'-'.join(f'{k}{v}' for k, v in config.items())}"
    meta = {**PAPER_METADATA, "inputs": names, "tile_size": tile, "provenance": {"arch": arch, **config}}
    ck = checkpoint.save(folder / f"{stem}.pt", net, meta)
    return net, export_checkpoint(ck, folder / f"{stem}.onnx")


def write_factors_sidecar(path: str, factors: Sequence[float], command: str) -> None:
    """Thresholds per rate as a metadata sidecar (``rate_factors``, in ``sdk.PREDICTED_RATES`` order) for
    ``rtp-export --retune``, written atomically, headed by the command that fitted them."""
    import yaml

    from rtp import sdk
    from rtp.sdk.files import atomic_output

    body = {"rate_factors": {r: round(float(v), 4) for r, v in zip(sdk.PREDICTED_RATES, factors)}}
    with atomic_output(path) as tmp:
        tmp.write_text(f"# threshold factors per rate, fitted by: {command}\n" + yaml.safe_dump(body, sort_keys=False),
                       encoding="utf-8")


def save_figure(fig: Any, path: str | Path) -> None:
    """Write a benchmark's matplotlib figure (laid out, 110 dpi, its folder made), close it and say where. Written
    atomically: a run stopped while it writes leaves the figure there before (docs/ embeds some), not half a PNG."""
    import matplotlib.pyplot as plt

    from rtp.sdk.files import atomic_output

    path = Path(path)
    fig.tight_layout()
    try:
        with atomic_output(path) as tmp:  # (its temporary name ends in .tmp: the format is the path's)
            fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".").lower() or "png")
    finally:
        plt.close(fig)
    print(f"\nwrote {path}")


def module_at_revision(rev: str, path: str, name: str, replace: dict[str, str] | None = None) -> Any:
    """The module ``path`` (``sdk/_channels.py``) as it was at git revision ``rev``, imported as ``name``
    (``rtp.sdk._channels_then``: its relative imports resolve in that package); a :class:`UsageError` (exit 2)
    where git cannot show it. For the benchmarks' ``--against REV``. ``replace``: texts
    of the source replaced first (``{"from ._reproject import": "from ._reproject_then import"}``: a module
    of that revision importing another module of the same revision, loaded before it)."""
    import importlib.util
    import subprocess
    import sys
    import tempfile

    root = Path(__file__).resolve().parents[1]
    src = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=root, capture_output=True, encoding="utf-8",
                         errors="replace")  # (a source is UTF-8 whatever the locale: sdk/_errors.py's tree)
    if src.returncode:
        raise UsageError(f"--against {rev}: git cannot show {path} there "
                         f"({src.stderr.strip().splitlines()[-1] if src.stderr.strip() else 'no output'})")
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / f"{name.rpartition('.')[2]}.py"
        text = src.stdout
        for old, new in (replace or {}).items():
            if old not in text:
                raise UsageError(f"--against {rev}: {path} there has no {old!r}")
            text = text.replace(old, new)
        file.write_text(text, encoding="utf-8")  # (Python reads a source as UTF-8)
        spec = importlib.util.spec_from_file_location(name, file)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    return module
