"""Property-based fuzzing of the command line (hypothesis): ``rtp.cli.main`` and ``rtp.cli.export_main``
called in-process with generated argument lists for the subcommands whose main input does not exist
(``rtp info``, ``evaluate``, ``targets``, ``train``, ``preview``, ``metric``, ``predict``, ``scenes`` and
``rtp-export``), every other flag
given a hostile value (empty, negative, huge, NaN, unicode, NUL bytes, a folder where a file is asked,
a file that is not what is asked). Whatever arrives, the command must fail fast the way docs/errors.md
says: one line ``PROG: error: MESSAGE`` on stderr, exit code 2 or 1, no traceback, no exception out of
``main`` (argparse's own ``SystemExit(2)`` is its usage error).

The subcommands that render (``play``, ``capture``, ``demo``) are given a map that no split of
scenes.yaml lists, so none can start long work, nor can ``scenes fetch`` download.
Every path is relative to a fresh temporary folder that is the working directory while a command
runs, so nothing is written into the repository. Values never name a shipped model.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import tempfile
import threading
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtp import cli

from .fuzzing import scaled

#: Seconds one command may take before it counts as a hang (its input is missing: it must fail at once).
HANG_S = 10.0
EXAMPLES = 25

# -- the scratch folder's contents (made fresh for each example) --------------------------------------

_FIXTURES: dict[str, bytes | None] = {
    "folder": None,                         # a folder where a file is asked
    "dir.onnx": None,                       # a folder named like a model
    "dir.pt": None,
    "dir.yaml": None,
    "dir.png": None,
    "note.txt": b"not a model\n",           # files that are not what is asked
    "empty.onnx": b"",
    "junk.onnx": b"\x08\x07junk\xff\x00" * 8,
    "junk.pt": b"PK\x03\x04not a zip\x00",
    "bad.yaml": b"[: {\n",
    "list.yaml": b"- 1\n- 2\n",
    "nul.yaml": b"metric: \x00\n",
    "notdata/samples.json": b"{not json",   # a folder that is not a dataset
    "bad.png": b"\x89PNG\r\n\x1a\n" + b"\x00junk" * 8,  # an image cut short after its signature
}

_MISSING = ["missing", "missing.onnx", "missing.pt", "missing/deeper/x.onnx", "nope_dir", "missing.yaml",
            "missing/out.png"]
_EXISTING = [k for k in _FIXTURES] + ["notdata", "."]


def _populate(root: Path) -> None:
    for name, content in _FIXTURES.items():
        path = root / name
        if content is None:
            path.mkdir(parents=True, exist_ok=True)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(content)


# -- hostile values -------------------------------------------------------------------------------

_SPECIAL = [
    "", " ", "\t", "\n", "-", "--", "0", "-0", "1", "-1", "2", "-2", "0.0", "-0.0", "1.5", "nan", "NaN", "-nan",
    "inf", "-inf", "Infinity", "1e309", "-1e309", "1e-320", "1e308", "9" * 40, "-" + "9" * 40, "2**31",
    "2147483648", "-2147483649", "18446744073709551616", "0x10", "1_000", "1e3", "16.0", "½", "١٦", "٣",
    "\u00a0", "e", "true", "none", "None", "null", "[]", "{}", "a,b", ",", ",,", "a" * 300, "x/" * 50,
    "\x00", "a\x00b", "missing\x00.onnx", "\udcff", "\ud800", "é.onnx", "🙂", "𝟙𝟞", "shipped", "auto",
    "ray://", "host:99999", "paper", "fast", "1x2", "1x2,2x1,,", "reprojected.r,,seen", "jnyang,,",
    "1,2", "\\", "~", "~/x", "$HOME", "*", "?", "../", "./.", "//", "model.pt", "out.onnx", "out.png",
    "out.xyz", "out.", ".png",
]

hostile = st.one_of(
    st.sampled_from(_SPECIAL), st.sampled_from(_SPECIAL), st.sampled_from(["--", "-", "\x00", ""]),
    st.sampled_from(_EXISTING + _MISSING),
    st.integers(-(2**70), 2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=12),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=6).map(lambda s: s + "\x00"),
)
#: A value for a flag that takes a path: mostly paths, sometimes anything.
paths = st.one_of(st.sampled_from(_EXISTING + _MISSING), hostile)
#: A value for a flag that takes a number: mostly number-like text.
numbers = st.one_of(
    st.sampled_from([s for s in _SPECIAL if len(s) < 45]),
    st.integers(-(2**70), 2**70).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    hostile,
)

Flag = tuple[str, st.SearchStrategy[str] | None]  # (flag, value) - None: a switch


def _argv(prefix: Sequence[str], required: Sequence[Flag], optional: Sequence[Flag],
          output: Sequence[str] = ("-q", "--no-progress")) -> st.SearchStrategy[list[str]]:
    """``prefix``, then ``required`` (each usually given, valid or hostile) and a few of ``optional``
    (each with a hostile value), in any order; values as ``--flag=value`` so one starting with '-' is
    still the flag's value and not a flag of its own."""

    def one(flag: str, values: st.SearchStrategy[str] | None) -> st.SearchStrategy[list[str]]:
        if values is None:
            return st.just([flag])
        return values.map(lambda v: [f"{flag}={v}"])

    req = [st.one_of(one(f, v), one(f, v), one(f, v), st.just([])) for f, v in required]
    opt = st.lists(st.sampled_from([*optional, *[(o, None) for o in output]]), max_size=6, unique_by=lambda fv: fv[0])
    return st.tuples(st.tuples(*req) if req else st.just(()), opt).flatmap(
        lambda ro: st.tuples(*[st.just(r) for r in ro[0]], *[one(f, v) for f, v in ro[1]]).flatmap(
            lambda groups: st.permutations(list(groups)).map(
                lambda perm: [*prefix, *(a for g in perm for a in g)])))


# -- the subcommands -------------------------------------------------------------------------------

_INFO = _argv(["info", "missing.onnx"], [], [("--metadata", paths), ("--json", None)])

_EVALUATE = _argv(
    ["evaluate", "missing.onnx"],
    [("--data", st.one_of(st.just("missing_dir"), paths))],
    [("--out", paths), ("--scene", hostile), ("--metadata", paths), ("--threshold", numbers),
     ("--unseen-fraction", numbers), ("--no-baselines", None), ("--plots", None), ("--plot-sample", hostile),
     ("--max-samples", numbers), ("--tile-size", numbers)])

_TARGETS = _argv(
    ["targets", "missing_dir"], [],
    [("--metrics", hostile), ("--ppd", numbers), ("--weber-l", numbers), ("--workers", numbers),
     ("--ray", hostile), ("--ray", None)])

_TRAIN_VALUES = [
    ("--config", paths), ("--tile", numbers), ("--outputs", hostile), ("--inputs", hostile),
    ("--transform", hostile), ("--k", numbers), ("--arch", hostile), ("--width", numbers), ("--depth", numbers),
    ("--stem", numbers), ("--stem-layers", numbers), ("--energy-norm", None), ("--grow", numbers),
    ("--separable", None), ("--separable-tail", None), ("--tail-width", numbers), ("--head-width", numbers),
    ("--context-pool", numbers), ("--coarse", numbers), ("--coarse-width", numbers), ("--block-contrast", hostile),
    ("--contrast-cell", numbers), ("--contrast-max", None), ("--max-width", numbers), ("--augment", None),
    ("--mirror", None), ("--head", hostile), ("--loss", hostile), ("--quantile", numbers), ("--focus", numbers),
    ("--ema", numbers), ("--teachers", paths), ("--distill", numbers), ("--aux-metrics", hostile),
    ("--aux-weight", numbers), ("--steps", numbers), ("--batch", numbers), ("--crop", numbers),
    ("--context", numbers), ("--lr", numbers), ("--optimizer", hostile), ("--schedule", hostile),
    ("--weight-decay", numbers), ("--seed", numbers), ("--safety-quantile", numbers), ("--max-samples", numbers),
    ("--per-scene", numbers), ("--val-scenes", hostile), ("--threshold", numbers), ("--splits", paths),
]
_METRICS = ["flip", "jnflip", "psnr", "lpips", "yang", "jnyang"]
_TRAIN = _argv(
    ["train"],
    [("--data", st.one_of(st.just("missing_dir"), st.just("missing_dir,notdata"), paths)),
     ("--metric", st.one_of(st.sampled_from(_METRICS), hostile)),
     ("--out", st.one_of(st.just("m.pt"), paths))],
    _TRAIN_VALUES)

_PREVIEW = _argv(
    ["preview", "missing_dir"],
    [("--out", st.one_of(st.just("out.png"), paths))],
    [("--sample", hostile), ("--scale", numbers)])

_EXPORT = _argv(
    ["missing.pt"], [],
    [("-o", paths), ("--output", paths), ("--opset", numbers), ("--metadata", paths), ("--adopt", paths),
     ("--dynamic", None), ("--replace", None), ("--restamp", paths), ("--no-finite-probe", None),
     ("--one-input", None), ("--strip-probe", paths), ("--join-planes", paths), ("--retune", paths)])


# The commands that render: their map is one no split lists (the main input that does not exist), so
# whatever the other flags say they must stop before any rendering. capture's --split would replace the
# map, and is mutually exclusive with --scene: given, it is a usage error.
_UNLISTED = "nosuchmap"

_PLAY = _argv(
    ["play", _UNLISTED], [],
    [("--methods", hostile), ("--path", hostile), ("--frames", numbers), ("--fps", numbers), ("--seed", numbers),
     ("--size", hostile), ("--tile-size", numbers), ("--fail-metric", hostile), ("--fail-threshold", numbers),
     ("--no-sweep", None), ("--flip-every", numbers), ("--composite", None), ("--out", paths), ("--no-plots", None),
     ("--no-animation", None), ("--workers", numbers), ("--open-loop", None), ("--cache-dir", paths)])

_CAPTURE = _argv(
    ["capture", f"--scene={_UNLISTED}"],
    [("--out", st.one_of(st.just("data_out"), paths))],
    [("--per-scene", numbers), ("--size", hostile), ("--profiles", hostile), ("--workers", numbers),
     ("--ray", hostile), ("--seed", numbers), ("--placement", hostile), ("--cache-dir", paths), ("--splits", paths),
     ("--split", hostile), ("--scene", hostile)])

_DEMO = _argv(
    ["demo", f"--scene={_UNLISTED}"], [],
    [("--model", paths), ("--threshold", numbers), ("--size", hostile), ("--frames", numbers), ("--seed", numbers),
     ("--out", paths), ("--cache-dir", paths)])


# rtp scenes: fetch is given a map no split lists (--map appends, so it stays), list a split file that
# does not exist (or, when a later --splits replaces it, whatever the draw gives: no fixture is one).
_SCENES_FETCH = _argv(
    ["scenes", "fetch", f"--map={_UNLISTED}"], [],
    [("--map", hostile), ("--splits", paths), ("--cache-dir", paths), ("--convert", None)])
_SCENES_LIST = _argv(
    ["scenes", "list", "--splits=missing.yaml"], [], [("--splits", paths), ("--cache-dir", paths), ("--json", None)])

# rtp metric: no fixture is a readable image, so whichever metric, one image is missing or unreadable.
_METRIC = st.tuples(st.one_of(st.sampled_from(_METRICS), hostile), paths, paths).flatmap(
    lambda mrt: _argv(["metric", *mrt], [], [("--out", paths), ("--tile", numbers), ("--json", None)]))


# rtp predict: no fixture is an .npz of G-buffers, so a frame (of one, or of a sequence of several) is missing or
# unreadable, or a folder holds none (--write-example, which renders and writes one, is not drawn).
_PREDICT = st.lists(st.one_of(st.just("missing.npz"), paths), min_size=1, max_size=3).flatmap(
    lambda frames: _argv(["predict", *frames], [],
                         [("--model", hostile), ("--threshold", numbers), ("--tile-size", numbers),
                          ("--allowed", hostile), ("--out", paths), ("--json", None), ("--size", hostile),
                          ("--seed", numbers), ("--frames", numbers), ("--depth-kind", hostile)]))


# rtp adapters check: an adapter in a module that does not exist (nothing is drawn), whatever the options;
# rtp adapters list takes no input to miss, so it is not here.
_ADAPTERS_CHECK = st.one_of(st.just("no_such_module:Adapter"), st.just("no-such-adapter")).flatmap(
    lambda spec: _argv(["adapters", "check", spec], [],
                       [("--size", hostile), ("--model", paths), ("--tolerance", hostile), ("--json", None)]))


# -- running one command ---------------------------------------------------------------------------

class Hang(BaseException):
    """A command that did not return within HANG_S."""


def _call(entry: Callable[[list[str]], int], argv: list[str]) -> tuple[int | None, str, BaseException | None]:
    """Run ``entry(argv)`` in a fresh scratch folder (the working directory), with stdout and stderr
    captured and a watchdog: (return code or argparse's SystemExit code, stderr, any other escape)."""
    err, out = io.StringIO(), io.StringIO()
    with tempfile.TemporaryDirectory(prefix="rtp-fuzz-cli-") as tmp:
        _populate(Path(tmp))
        main_thread = threading.current_thread() is threading.main_thread()

        def alarm(_signum: int, _frame: Any) -> None:
            raise Hang(f"no answer within {HANG_S:g} s")

        old = signal.signal(signal.SIGALRM, alarm) if main_thread else None
        if main_thread:
            signal.setitimer(signal.ITIMER_REAL, HANG_S)
        # (a path option's leading ~ is the home folder: `--out ~/x` writes in the scratch folder, not the real home)
        home = os.environ.get("HOME")
        os.environ["HOME"] = tmp
        try:
            with (contextlib.chdir(tmp), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out),
                  warnings.catch_warnings()):
                warnings.simplefilter("ignore")
                try:
                    return entry(argv), err.getvalue(), None
                except SystemExit as exc:
                    code = exc.code if isinstance(exc.code, int) else None
                    return (code if code is not None else -1), err.getvalue(), (None if code == 2 else exc)
                except Exception as exc:  # noqa: BLE001 - the point: any escape is a bug
                    return None, err.getvalue(), exc
        finally:
            if home is None:
                os.environ.pop("HOME", None)
            else:
                os.environ["HOME"] = home
            if main_thread:
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, old)


def _check(entry: Callable[[list[str]], int], argv: list[str], prefixes: tuple[str, ...]) -> None:
    rc, stderr, escaped = _call(entry, argv)
    where = ""
    if escaped is not None:
        import traceback

        frames = traceback.extract_tb(escaped.__traceback__)
        if frames:
            where = f" at {frames[-1].filename}:{frames[-1].lineno}"
    if escaped is not None:  # chained: hypothesis tells escapes from different places apart
        raise AssertionError(f"{argv!r}: {type(escaped).__name__}: {escaped}{where}") from escaped
    lines = [line for line in stderr.splitlines() if line.strip()]
    last = lines[-1] if lines else ""
    assert rc in (1, 2), f"{argv!r}: exit code {rc!r}, stderr {stderr[-500:]!r}"
    assert "Traceback" not in stderr, f"{argv!r}: a traceback on stderr: {stderr[-1500:]}"
    assert last.startswith(prefixes), f"{argv!r}: last stderr line {last!r} does not start with {prefixes}"


_SETTINGS = settings(max_examples=scaled(EXAMPLES), deadline=None, database=None, suppress_health_check=list(HealthCheck),
                     report_multiple_bugs=False)


def _rtp(sub: str) -> tuple[str, ...]:
    return (f"rtp {sub}: error: ", "rtp: error: ")


CASES = [
    ("info", _INFO),
    ("evaluate", _EVALUATE),
    ("targets", _TARGETS),
    ("train", _TRAIN),
    ("preview", _PREVIEW),
    ("play", _PLAY),
    ("capture", _CAPTURE),
    ("demo", _DEMO),
    ("metric", _METRIC),
    ("predict", _PREDICT),
    ("scenes fetch", _SCENES_FETCH),
    ("scenes list", _SCENES_LIST),
    ("adapters check", _ADAPTERS_CHECK),
]


@pytest.mark.parametrize(("sub", "strategy"), CASES, ids=[c[0] for c in CASES])
def test_rtp_subcommand_with_missing_input_fails_in_one_line(sub: str, strategy: st.SearchStrategy[list[str]]) -> None:
    @_SETTINGS
    @given(strategy)
    def run(argv: list[str]) -> None:
        _check(cli.main, argv, _rtp(sub))

    run()


def test_rtp_export_with_missing_checkpoint_fails_in_one_line() -> None:
    @_SETTINGS
    @given(_EXPORT)
    def run(argv: list[str]) -> None:
        _check(cli.export_main, argv, ("rtp-export: error: ",))

    run()


@pytest.mark.parametrize("argv", [
    ["info", "missing.onnx"],
    ["evaluate", "missing.onnx", "--data", "missing_dir"],
    ["targets", "missing_dir"],
    ["train", "--data", "missing_dir", "--metric", "jnyang", "--out", "m.pt"],
    ["preview", "missing_dir", "--out", "out.png"],
], ids=lambda a: a[0])
def test_rtp_plain_missing_input(argv: list[str]) -> None:
    _check(cli.main, argv, _rtp(argv[0]))


def test_rtp_export_plain_missing_checkpoint() -> None:
    _check(cli.export_main, ["missing.pt"], ("rtp-export: error: ",))


#: Shrunk failures the fuzz found (kept: each fails until the command refuses it in one line).
#: ``--flag=--``: argparse hands the flag an empty list instead of a string; a name over 255 bytes:
#: ``os.stat`` raises ENAMETOOLONG inside an argparse ``type=`` check, outside the error policy.
FOUND = [
    ["targets", "missing_dir", "--ppd=--"],
    ["targets", "missing_dir", "--workers=--"],
    ["evaluate", "missing.onnx", "--data=missing_dir", "--scene=--"],
    ["train", "--data=missing_dir", "--metric=jnyang", "--out=m.pt", "--aux-metrics=--"],
    ["train", "--data=missing_dir", "--metric=jnyang", "--out=m.pt", "--teachers=--"],
    ["train", "--data=missing_dir", "--metric=jnyang", "--out=m.pt", "--val-scenes=--"],
    ["evaluate", "missing.onnx", "--data=missing_dir", "--out=" + "a" * 256],
    ["train", "--data=missing_dir", "--metric=jnyang", "--out=" + "a" * 256],
    # rtp metric: a NUL in an image path was Pillow's ValueError; a newline in a path or in an argument
    # argparse quotes broke the one-line error (the error printer escapes what is not printable now)
    ["metric", "flip", "\x00", "folder"],
    ["metric", "flip", "\n", "folder"],
    ["metric", "flip", "folder", "--", "--json", "--out=\n", "-q"],
    # a NUL in the scene cache's path was the system's ValueError (now refused while parsing)
    ["scenes", "fetch", "--map=nosuchmap", "--cache-dir=\x00"],
    ["play", "nosuchmap", "--cache-dir=a\x00b"],
    ["scenes", "fetch", "--map=nosuchmap", "--cache-dir=\ud800"],
    # a literal "--" positional after the "--" that ends the options reached the command as [] (Python
    # 3.11's argparse strips it), Pillow's open([]) an AttributeError (RTP_FUZZ_SCALE=10, 2026-12-03)
    ["metric", "flip", "--", "--", "-q"],
    ["metric", "flip", "--", "--", "--"],
]


@pytest.mark.parametrize("argv", FOUND, ids=[f"{a[0]}-{a[-1][:16]!r}" for a in FOUND])
def test_found_cases(argv: list[str]) -> None:
    _check(cli.main, argv, _rtp(" ".join(argv[:2]) if argv[0] == "scenes" else argv[0]))
