"""The command line's one policy: every subcommand's help exits 0 and shows its defaults, the same
error class gives the same exit code and the same one-line message in every entry point (``rtp``,
``rtp scenes``, ``rtp-export``), and the choices come from the shared facts, not from lists of their own."""

from __future__ import annotations

import argparse
import ast
import contextlib
import re
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.cli import build_export_parser, build_parser, export_main, main
from rtp.cli._run import option_flags

from .conftest import base_metadata
from .test_errors_doc import all_errors

ROOT = Path(__file__).resolve().parents[1]


def _commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command path of a parser, found from the parser itself: (), ("info",), ("scenes", "fetch"), ..."""
    out = [prefix]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _commands(sub, (*prefix, name))
    return out


def _subparser(parser: argparse.ArgumentParser, command: Sequence[str]) -> argparse.ArgumentParser:
    for name in command:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    return parser


def _option(command: Sequence[str], dest: str) -> argparse.Action:
    return next(a for a in _subparser(build_parser(), command)._actions if a.dest == dest)


COMMANDS = [("rtp", c) for c in _commands(build_parser())] + [("rtp-export", ())]
ENTRY: dict[str, tuple[Callable[[Sequence[str] | None], int], Callable[[], argparse.ArgumentParser]]] = {
    "rtp": (main, build_parser), "rtp-export": (export_main, build_export_parser)}


def test_the_parser_has_every_command() -> None:
    assert {c[0] for _, c in COMMANDS if c} >= {"info", "scenes", "capture", "preview", "targets", "train", "evaluate",
                                                "demo", "metric"}
    assert ("rtp", ("scenes", "fetch")) in COMMANDS and ("rtp", ("scenes", "list")) in COMMANDS


@pytest.mark.parametrize(("prog", "command"), COMMANDS, ids=lambda c: " ".join(c) if isinstance(c, tuple) else c)
def test_help_exits_0_and_shows_defaults(prog: str, command: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    entry, build = ENTRY[prog]
    with pytest.raises(SystemExit) as exc:
        entry([*command, "--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert text.startswith(f"usage: {' '.join((prog, *command))}")
    for action in _subparser(build(), command)._actions:
        # (by identity: a default of 0, `--seed`'s, equals False, and its help did not show it)
        if (any(action.default is d for d in (None, False, argparse.SUPPRESS)) or not action.option_strings
                or action.required):
            continue
        assert action.help, (command, action.dest)
        # the help states the default itself, or the formatter appends it
        assert "default:" in action.help or f"(default: {action.default})" in text, (command, action.dest)


def _help_examples() -> list[tuple[str, tuple[str, ...], list[str]]]:
    """``(prog, command, argv)`` of every example of every help's epilog (``examples:``, a command a line, its
    description after two spaces or ``#``, commands joined by ``&&`` split)."""
    import shlex

    out = []
    for prog, command in COMMANDS:
        epilog = _subparser(ENTRY[prog][1](), command).epilog or ""
        _, found, examples = epilog.partition("examples:\n")
        assert found or "examples" not in epilog, (prog, command)
        for line in examples.splitlines():
            text = re.split(r"\s{2,}|\s#", line.strip())[0]
            for part in text.split("&&"):
                if part.strip().startswith(("rtp ", "rtp-export ")):
                    out.append((prog, command, shlex.split(part)))
    return out


def test_the_examples_of_every_help_run_as_written(capsys: pytest.CaptureFixture[str]) -> None:
    """Every example an epilog gives parses (its flags, choices and metrics exist), and a dataset an epilog captures
    and then trains on holds two scenes or more: `rtp train` holds out whole scenes for validation, and `rtp --help`'s
    `rtp capture --scene procedural:1 ... --out data/toy` then `rtp train --data data/toy` failed with "data/toy holds
    one scene", the first time a reader followed it."""
    from rtp.cli._main import _names

    examples = _help_examples()
    assert len(examples) >= 20 and {c for _, c, _ in examples} >= {(), ("import",), ("predict",), ("play",)}
    for prog, command, argv in examples:
        build = ENTRY[prog][1]
        try:
            args = build().parse_args(argv[1:])
        except SystemExit:
            pytest.fail(f"`{' '.join((prog, *command))} --help`'s example {' '.join(argv)!r} is refused: "
                        f"{capsys.readouterr().err.strip().splitlines()[-1:]}")
        if argv[1:2] == ["capture"]:  # what the same help then trains on
            trained = [a for p, c, a in examples if (p, c) == (prog, command) and a[1:2] == ["train"]
                       and build().parse_args(a[1:]).data == args.out]
            if trained and not args.split:
                assert len(_names(args.scene)) >= 2, f"{' '.join(argv)}: one scene, then {' '.join(trained[0])}"


def test_a_palette_with_nothing_to_draw_is_refused_in_every_command(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """`--palette` colours a picture the command draws only with another option; given without it, it is refused
    (exit 2, naming --palette), not taken and ignored: `rtp predict FRAME --palette cvd` without --out printed the
    rates as if the colours had been used. Every command with --palette is here (rtp demo always draws)."""
    nothing_drawn = {
        ("evaluate",): ["evaluate", "jnyang", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "ev")],
        ("play",): ["play", "procedural:0", "--no-plots", "--out", str(tmp_path / "play")],
        ("predict",): ["predict", str(tmp_path / "frame.npz")],
    }
    with_palette = {c for _, c in COMMANDS if any(a.dest == "palette" for a in _subparser(build_parser(), c)._actions)}
    assert with_palette == {*nothing_drawn, ("demo",)}
    for command, argv in nothing_drawn.items():
        assert main([*argv, "--palette", "cvd"]) == 2, command
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert err.startswith(f"rtp {command[0]}: error: --palette cvd"), err
    assert not any(tmp_path.iterdir())  # (refused before any work)


def test_rtp_alone_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:  # a usage error, with the commands rather than "COMMAND is required"
        main([])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "usage: rtp" in err and "capture" in err and "play" in err and "examples:" in err
    for argv in (["scenes"], ["weights"], ["info"]):  # the actions likewise; a command alone: argparse's error
        with pytest.raises(SystemExit) as exc:
            main(argv)
        err = capsys.readouterr().err
        assert exc.value.code == 2
        assert ("fetch" in err and "list" in err) if argv[0] != "info" else "required: model" in err, err


def test_unknown_arguments_are_named_by_the_command_given_them(capsys: pytest.CaptureFixture[str]) -> None:
    """`PROG: error: ...` names the command, as every other error does (argparse's own said `rtp: error:`)."""
    for argv, prog in ((["info", "jnyang", "extra"], "rtp info"), (["scenes", "fetch", "nosuch"], "rtp scenes fetch"),
                       (["-v", "predict", "x.npz", "--bogus"], "rtp predict")):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        err = capsys.readouterr().err
        assert exc.value.code == 2 and f"{prog}: error: unrecognized arguments: {argv[-1]}" in err, err


def test_the_dataset_folder_is_data_or_dash_dash_data_in_every_command(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp train` and `rtp evaluate` take the dataset as --data; `rtp targets` and `rtp preview` took it only as a
    positional DATA, so `rtp targets --data data` pasted between them was "unrecognized arguments: --data". Both
    spellings are taken now; none, or two different folders, are named."""
    import rtp.capture

    seen: list[str] = []
    monkeypatch.setattr(rtp.capture, "compute_targets", lambda data, *a, **k: seen.append(str(data)) or 0)
    for argv in (["targets", str(tmp_path)], ["targets", "--data", str(tmp_path)],
                 ["targets", str(tmp_path), "--data", f"{tmp_path}/"]):
        assert main([*argv, "--metrics", "psnr", "-q"]) == 0, capsys.readouterr().err
    assert seen == [str(tmp_path)] * 3
    assert main(["preview", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "p.png")]) == 2
    assert f"rtp preview: error: no dataset folder at {str(tmp_path / 'none')!r}" in capsys.readouterr().err
    assert main(["targets", "--metrics", "psnr"]) == 2
    assert "rtp targets: error: the dataset folder is required: DATA (or --data DATA)" in capsys.readouterr().err
    assert main(["targets", str(tmp_path), "--data", str(tmp_path / "other")]) == 2
    assert "two dataset folders given" in capsys.readouterr().err and seen == [str(tmp_path)] * 3


def test_a_bad_value_is_named_by_its_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The library's checks name their Python arguments (flip_every, paths, ppd); on the command line the message
    names the flag that set it (docs/errors.md), and one about something else keeps its words."""
    for argv, said in ((["play", "procedural", "--flip-every", "-1"], "rtp play: error: --flip-every: expected"),
                       (["play", "procedural", "--path", "foo"], "rtp play: error: --path: unknown profile 'foo'"),
                       (["targets", str(tmp_path), "--ppd", "-3"], "rtp targets: error: --ppd must be"),
                       (["targets", str(tmp_path), "--weber-l", "-1"], "rtp targets: error: --weber-l (environment"),
                       (["play", "procedural", "--methods", "nosuch"], "rtp play: error: method 'nosuch': not one")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert said in err, err
    flags = option_flags(_subparser(build_parser(), ("play",)))
    assert flags["paths"] == flags["path"] == "--path" and flags["tile_size"] == "--tile-size"
    assert "methodss" not in flags and "help" not in flags


@pytest.mark.parametrize("argv", [["-m", "rtp", "--help"], ["-m", "rtp.cli", "scenes", "--help"],
                                  ["-m", "rtp.cli", "scenes", "fetch", "--help"],
                                  ["-m", "rtp.cli.export", "--help"]], ids=" ".join)
def test_help_of_the_installed_entry_points(argv: list[str]) -> None:
    r = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("usage: ") and not r.stderr, r.stderr


def test_rtp_export_help_and_versions(capsys: pytest.CaptureFixture[str]) -> None:
    for entry, prog in ((export_main, "rtp-export"), (main, "rtp")):
        with pytest.raises(SystemExit) as exc:
            entry(["--version"])
        assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"{prog} {sdk.__version__}"
    assert build_export_parser().prog == "rtp-export"


def test_python_m_rtp_and_the_package_version() -> None:
    r = subprocess.run([sys.executable, "-m", "rtp", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == f"rtp {sdk.__version__}", r.stderr
    # `import rtp` is light: it imports no room until asked for its version
    code = "import sys, rtp; light = 'rtp.sdk' not in sys.modules; print(light, rtp.__version__)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.stdout.split() == ["True", sdk.__version__], r.stderr
    assert sdk.__version__ not in ("", "0+unknown")


def test_common_options_go_before_or_after_the_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["-q", "info", "nope.onnx"], ["info", "nope.onnx", "-q"], ["info", "-v", "nope.onnx"]):
        assert main(argv) == 2
    assert "Traceback" in capsys.readouterr().err  # -v shows it


def test_twice_verbose_logs_rtps_own_details_and_nothing_else(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``-vv`` (or ``-v`` before and after the command) adds rtp's DEBUG records (each metric's and
    each frame's details), never a third-party library's; ``-v`` stays progress only."""
    import logging

    from PIL import Image

    from rtp.cli._run import _logging

    rng = np.random.default_rng(0)
    a = (rng.random((64, 96, 3)) * 255).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "a.png")
    Image.fromarray(255 - a).save(tmp_path / "b.png")
    pair = ["flip", str(tmp_path / "a.png"), str(tmp_path / "b.png")]
    detail = "DEBUG rtp.metrics: FLIP on 1 image(s) of 96x64"
    for argv, shown in ((["-vv", "metric", *pair], True), (["-v", "metric", "-v", *pair], True),
                        (["metric", "-vv", *pair], True), (["-v", "metric", *pair], False), (["metric", *pair], False)):
        assert main(argv) == 0
        assert (detail in capsys.readouterr().err) == shown, argv
    with _logging(argparse.Namespace(verbose=2, quiet=False)):
        logging.getLogger("PIL.PngImagePlugin").debug("third-party chatter")
        logging.getLogger("rtp.capture").debug("rtp's own detail")
        logging.getLogger("PIL.PngImagePlugin").info("third-party progress")
    err = capsys.readouterr().err
    assert "rtp's own detail" in err and "third-party progress" in err and "chatter" not in err


# -- one error class, one exit code, one message, in every entry point ------------------------

ERRORS = sorted(all_errors().items())


def _raiser(error: BaseException) -> Callable[..., Any]:
    def body(*_: Any, **__: Any) -> Any:
        raise error

    return body


def _entry_points(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, error: BaseException) -> list[tuple[str, Callable[[
        list[str]], int], list[str]]]:
    """The three entry points, each made to meet ``error`` in the library call its command makes:
    (the prog its messages start with, the entry point, its arguments)."""
    import rtp.capture.scenes
    import rtp.export

    monkeypatch.setattr(sdk, "load", _raiser(error))
    monkeypatch.setattr(rtp.capture.scenes, "fetch", _raiser(error))
    monkeypatch.setattr(rtp.export, "export_checkpoint", _raiser(error))
    return [("rtp info", main, ["info", "model.onnx"]),
            ("rtp scenes fetch", main, ["scenes", "fetch", "--cache-dir", str(tmp_path)]),
            ("rtp-export", export_main, [str(tmp_path / "model.pt")])]


@pytest.mark.parametrize(("name", "cls"), ERRORS, ids=[n for n, _ in ERRORS])
def test_one_error_class_one_exit_code_in_every_entry_point(name: str, cls: type[sdk.RtpError], tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    error = cls("what went wrong")
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, error):
        assert entry(argv) == sdk.exit_code(error) == cls.exit_code, prog
        assert capsys.readouterr().err == f"{prog}: error: what went wrong\n"  # one line, no traceback
        assert entry([*argv, "--verbose"]) == cls.exit_code, prog
        err = capsys.readouterr().err
        assert err.startswith("Traceback") and f"{name}: what went wrong" in err, prog
        assert err.endswith(f"{prog}: error: what went wrong\n"), prog


def test_interrupts_exit_130_and_bugs_propagate(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, KeyboardInterrupt()):
        assert entry(argv) == 130, prog
        assert capsys.readouterr().err == f"{prog}: interrupted\n"
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, ZeroDivisionError("a bug")):
        with pytest.raises(ZeroDivisionError):  # not an rtp error: a bug, raised with its traceback (exit 1)
            entry(argv)
        assert "error:" not in capsys.readouterr().err, prog


def test_an_interrupted_resumable_command_says_what_it_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C in capture, targets, train or play says, after "interrupted", what the job kept and that
    the same command goes on from it (it said "interrupted" alone, and a user could believe the work
    lost); each account is true: the rerun resumes from what it names."""
    from rtp.cli._run import Bar

    def interrupt_at(count: int) -> None:
        def update_to(self: Bar, n: int, total: int | None = None, **_: str) -> None:
            if n >= count:
                raise KeyboardInterrupt

        monkeypatch.setattr(Bar, "update_to", update_to)

    data = tmp_path / "data"
    capture = ["capture", "--scene", "procedural:1,procedural:2", "--per-scene", "2", "--size", "64x48", "--profiles",
               "slow", "--out", str(data), "-q"]
    interrupt_at(3)
    assert main(capture) == 130
    assert capsys.readouterr().err == (f"rtp capture: interrupted; 3 of 4 samples are in {data} (each written whole): "
                                       f"the same command captures the rest\n")
    interrupt_at(99)
    assert main(capture) == 0 and "1 sample written, 3 already there" in capsys.readouterr().out
    interrupt_at(2)
    assert main(["targets", str(data), "--metrics", "jnyang", "-q"]) == 130
    assert capsys.readouterr().err == ("rtp targets: interrupted; the targets of 2 of 4 samples are kept: the same "
                                       "command computes the rest\n")
    interrupt_at(99)  # (the resumed run says what it did and what was there; a metric named twice is named once)
    assert main(["targets", str(data), "--metrics", "jnyang,jnyang", "-q"]) == 0
    assert capsys.readouterr().out.endswith("targets computed for 2 samples (jnyang); 2 samples already had them\n")
    # a parameter of metrics not asked for was taken and ignored: refused, naming the metrics that use it
    for flag, value, words in (("--ppd", "40", "only flip and jnflip use"), ("--weber-l", "0.5", "of jnflip and jnyang")):
        assert main(["targets", str(data), "--metrics", "psnr", flag, value, "-q"]) == 2
        assert words in capsys.readouterr().err
    model = tmp_path / "m.pt"
    train = ["train", "--data", str(data), "--metric", "jnyang", "--val-scenes", "procedural:2", "--steps", "600",
             "--batch", "4", "--crop", "32", "--out", str(model), "-q"]
    from rtp.train import _loop

    real_validate = _loop._validate

    def interrupted_validation(*args: object, **kwargs: object) -> object:
        raise KeyboardInterrupt

    monkeypatch.setattr(_loop, "_validate", interrupted_validation)  # (before the first step)
    assert main(train) == 130
    assert capsys.readouterr().err == ("rtp train: interrupted; no checkpoint yet (no step was done): the same "
                                       "command starts again\n")
    monkeypatch.setattr(_loop, "_validate", real_validate)
    interrupt_at(260)  # (the steps since the last periodic checkpoint, at 250, are kept too)
    assert main(train) == 130
    assert capsys.readouterr().err == (f"rtp train: interrupted; {model} holds step 260 of 600: the same command "
                                       f"resumes there\n")
    resumed: list[int] = []
    monkeypatch.setattr(Bar, "update_to", lambda self, n, total=None, **_: resumed.append(n))
    assert main(train) == 0 and resumed[0] == 260 and resumed[-1] == 600  # (the bar starts where it stopped)
    play = tmp_path / "play"
    interrupt_at(1)  # (on the first path: it said "the paths played to their end are kept" of none)
    run = ["play", "procedural:1", "--frames", "3", "--methods", "full", "--size", "64x48", "--no-sweep", "--out",
           str(play), "-q"]
    assert main(run) == 130
    assert capsys.readouterr().err == (f"rtp play: interrupted; no path was played to its end, so none is kept in "
                                       f"{play} (each is kept as it ends): the same command plays them all\n")
    interrupt_at(4)  # on the second: the first is kept, and is still once the rerun has read it back
    for _ in range(2):
        assert main(run) == 130
        assert capsys.readouterr().err == (f"rtp play: interrupted; the path played to its end (slow) is kept in "
                                           f"{play}: the same command plays the rest (fast)\n")


def test_a_second_interrupt_while_the_account_is_made_still_says_interrupted(capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C pressed again while the interrupted command makes its account of what it kept (it reads
    its folder) is not a traceback in place of the first's line: it says "interrupted" and exits 130."""
    from rtp.cli._run import run_guarded

    def body() -> int:
        raise KeyboardInterrupt

    def account() -> str:
        raise KeyboardInterrupt  # the second Ctrl-C

    try:
        code = run_guarded("rtp capture", body, on_interrupt=lambda: account)
    except KeyboardInterrupt:
        pytest.fail("the second Ctrl-C escaped as a traceback")
    assert code == 130
    assert capsys.readouterr().err == "rtp capture: interrupted\n"


def test_an_interrupt_while_the_command_starts_says_interrupted(monkeypatch: pytest.MonkeyPatch,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C in the first half-second of a command, while rtp's modules load and its parser is built (before the
    command's own policy runs), was a KeyboardInterrupt traceback of the import it landed in: it says
    "interrupted" and exits 130, as later."""
    import rtp.cli._export
    import rtp.cli._main

    monkeypatch.setattr(rtp.cli._main, "build_parser", _raiser(KeyboardInterrupt()))
    monkeypatch.setattr(rtp.cli._export, "build_export_parser", _raiser(KeyboardInterrupt()))
    for prog, entry in (("rtp", main), ("rtp-export", export_main)):
        try:
            code = entry(["info", "model.onnx"] if entry is main else ["model.pt"])
        except KeyboardInterrupt:
            pytest.fail(f"{prog}: the interrupt escaped as a traceback")
        assert code == 130
        assert capsys.readouterr().err == f"{prog}: interrupted\n"


def test_a_path_the_system_refuses_is_one_line_and_other_os_errors_are_bugs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """An OSError about a path (a folder where a file was asked, a read-only place, a full disk) is the
    user's to fix: one line, 2 where the path itself is wrong, 1 where the job failed; an OSError without
    a path is a bug and keeps its traceback."""
    import errno

    cases = ((IsADirectoryError(errno.EISDIR, "Is a directory", "out"), 2),
             (OSError(errno.ENOSPC, "No space left on device", "big.onnx"), 1))
    for error, code in cases:
        for prog, entry, argv in _entry_points(monkeypatch, tmp_path, error):
            assert entry(argv) == code, prog
            err = capsys.readouterr().err
            assert err == f"{prog}: error: {error.strerror}: {error.filename!r}\n", err
    for _, entry, argv in _entry_points(monkeypatch, tmp_path, OSError("a bug")):
        with pytest.raises(OSError, match="a bug"):
            entry(argv)
    noted = OSError(errno.ENOSPC, "No space left on device", "a/b.npz")
    noted.add_note("(rtp: raised while working on sample 'a/b')")
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, noted):
        assert entry(argv) == 1, prog
        assert capsys.readouterr().err == (f"{prog}: error: No space left on device: 'a/b.npz' "
                                           "(rtp: raised while working on sample 'a/b')\n"), prog


def test_an_optional_module_not_installed_is_one_line_naming_its_extra(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A command run without the extra it needs (`rtp-export` without onnx, `rtp predict --out` on the runtime
    install without Pillow) was a ModuleNotFoundError's traceback and exit 1; it is a missing install: one line
    naming the extra, exit 2. An rtp module's own words around it are kept; any other module missing (rtp's own, a
    plugin's) and a module installed but broken (`cannot import name`) are bugs and keep their traceback."""
    installs = {"rtp info": "rtp[export]", "rtp scenes fetch": "rtp[export]", "rtp-export": "rtp[export]"}
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, ModuleNotFoundError("No module named 'onnx'",
                                                                                         name="onnx")):
        assert entry(argv) == 2, prog
        assert capsys.readouterr().err == (f"{prog}: error: this needs onnx, which is not installed: "
                                           f"pip install '{installs[prog]}'\n"), prog
        assert entry([*argv, "--verbose"]) == 2 and capsys.readouterr().err.startswith("Traceback"), prog
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, ModuleNotFoundError("No module named 'torch'",
                                                                                         name="torch")):
        assert entry(argv) == 2, prog  # (rtp-export's torch is its extra's; the others' training's)
        said = capsys.readouterr().err  # (and where torch's CPU build comes from: README, Set-up)
        assert ("pip install 'rtp[export]'; " if prog == "rtp-export" else "pip install 'rtp[train]'; ") in said, prog
        assert said.endswith("--extra-index-url https://download.pytorch.org/whl/cpu (README, Set-up)\n"), prog
    try:
        raise ImportError("the rtp reference renderer needs moderngl; install the extra: pip install 'rtp[moderngl]'") \
            from ModuleNotFoundError("No module named 'moderngl'", name="moderngl")
    except ImportError as err:
        wrapped = err
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, wrapped):
        assert entry(argv) == 2 and capsys.readouterr().err == f"{prog}: error: {wrapped}\n", prog
    for bug in (ModuleNotFoundError("No module named 'nothing_rtp_lists'", name="nothing_rtp_lists"),
                ImportError("cannot import name 'nothing' from 'torch'", name="torch")):
        for _, entry, argv in _entry_points(monkeypatch, tmp_path, bug):
            with pytest.raises(ImportError, match="nothing"):
                entry(argv)


def test_running_out_of_memory_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """numpy's MemoryError ("Unable to allocate ...") is the machine's limit, not a bug: one line, exit 1."""
    message = "Unable to allocate 30.5 GiB for an array with shape (1000000, 4, 64, 64) and data type float16"
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, MemoryError(message)):
        assert entry(argv) == 1, prog
        assert capsys.readouterr().err == f"{prog}: error: out of memory: {message}\n", prog
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, MemoryError()):
        assert entry(argv) == 1 and capsys.readouterr().err == f"{prog}: error: out of memory: an allocation failed\n"
    # a capture or targets worker's failure carries a note naming its scene or sample: kept on the one line
    noted = MemoryError(message)
    noted.add_note("(rtp: raised while working on scene 'procedural:6')")
    for prog, entry, argv in _entry_points(monkeypatch, tmp_path, noted):
        assert entry(argv) == 1, prog
        assert capsys.readouterr().err == (f"{prog}: error: out of memory: {message} "
                                           "(rtp: raised while working on scene 'procedural:6')\n"), prog


def test_arguments_that_would_fail_later_fail_while_parsing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Found by trying bad values: each used to fail after work had begun (or in a native crash, or
    with a library's traceback); now argparse refuses it (exit 2) and nothing is written."""
    (tmp_path / "file").write_text("x")
    folder = str(tmp_path / "folder")
    bad = [["demo", "--size", "99999999x16"], ["play", "procedural:0", "--size", "100000x16"],
           ["demo", "--seed", "-1"], ["play", "procedural:1", "--seed", "-1"],
           ["evaluate", "jnyang", "--data", folder, "--out", str(tmp_path / "file")],
           ["demo", "--out", str(tmp_path / "file")], ["capture", "--scene", "procedural:1", "--per-scene", "1",
                                                        "--out", str(tmp_path / "file" / "x")],
           ["train", "--data", folder, "--metric", "jnyang", "--out", str(tmp_path)],
           ["preview", folder, "--out", str(tmp_path / "p.xyz")], ["metric", "psnr", "a.png", "b.png", "--out", "x.xyz"],
           # a name list that names nothing (an unset shell variable) meant "all": every map fetched, both paths
           ["scenes", "fetch", "--map", "", "--cache-dir", folder], ["scenes", "fetch", "--map", ",", "--cache-dir", folder],
           ["capture", "--scene", " ", "--out", folder], ["play", "procedural:0", "--path", "", "--out", folder],
           ["evaluate", "jnyang", "--data", folder, "--scene", ""],
           ["train", "--data", folder, "--metric", "jnyang", "--out", str(tmp_path / "m.pt"), "--val-scenes", ""]]
    for argv in bad:
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2, argv
        assert "argument --" in capsys.readouterr().err, argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_jobs_check_their_values_before_they_write(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp targets --ppd -1` stored the bad value in the targets' manifest, which then refused every
    later run; `rtp capture` wrote a manifest for a scene it could not load or a size it could not draw;
    `rtp train` checked its learning rate and threshold only at its first save, 250 steps in."""
    data = tmp_path / "data"
    assert main(["capture", "--scene", "procedural:1", "--per-scene", "1", "--size", "64x48", "--out", str(data),
                 "-q"]) == 0
    for argv in (["targets", str(data), "--metrics", "flip", "--ppd", "-1"],
                 ["targets", str(data), "--metrics", "jnyang", "--weber-l", "-1"]):
        assert main([*argv, "-q"]) == 2
    assert not (data / "targets").exists()
    (tmp_path / "bad.glb").write_text("not a GLB")
    for scene in ("procedural:-1", "no_such_map", str(tmp_path / "missing.glb"), str(tmp_path / "bad.glb")):
        out = tmp_path / "c"
        assert main(["capture", "--scene", scene, "--per-scene", "1", "--size", "64x48", "--out", str(out), "-q"]) == 2
        assert not out.exists(), scene
        for command in (["demo", "--scene", scene], ["play", scene, "--frames", "3", "--methods", "full"]):
            assert main([*command, "--size", "64x48", "--out", str(out), "-q"]) == 2, (command, scene)
            assert not out.exists(), (command, scene)  # (an empty output folder was left before)
    for value in ("-1", "nan"):  # the SDK's range, as rtp predict, evaluate and play take it
        assert main(["demo", "--threshold", value, "--out", str(tmp_path / "d"), "-q"]) == 2
        assert "--threshold: expected a finite number in [0, 1e+06] for an error metric" in capsys.readouterr().err
        assert not (tmp_path / "d").exists()
    for flag, value in (("--lr", "-1"), ("--lr", "nan"), ("--threshold", "-1"), ("--threshold", "nan"),
                        ("--weight-decay", "-0.5"), ("--k", "0"), ("--safety-quantile", "2"),
                        ("--safety-quantile", "nan")):
        assert main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"), flag, value,
                     "-q"]) == 2, flag
        assert "expected" in capsys.readouterr().err
    for argv, words in ((["--quantile", "0.5"], "with loss quantile"), (["--distill", "0.5"], "teachers")):
        assert main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"), *argv,
                     "-q"]) == 2  # (taken and ignored before)
        assert words in capsys.readouterr().err
    assert not (tmp_path / "m.pt").exists()


def test_real_errors_exit_the_same_in_every_entry_point(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = str(tmp_path / "nope.onnx")
    assert main(["info", missing]) == sdk.ModelNotFoundError.exit_code == 2
    assert main(["evaluate", missing, "--data", str(tmp_path)]) == 2
    assert export_main([str(tmp_path / "nope.pt")]) == 2
    assert main(["scenes", "fetch", "--map", "no_such_map", "--cache-dir", str(tmp_path)]) == 2  # UnlistedMapError
    assert main(["scenes", "list", "--splits", str(tmp_path / "nope.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 5 and "Traceback" not in err
    for prefix in ("rtp info: error:", "rtp evaluate: error:", "rtp-export: error:", "rtp scenes fetch: error:",
                   "rtp scenes list: error:"):
        assert prefix in err
    for argv in (["capture", "--per-scene", "0", "--out", str(tmp_path)], ["scenes"], ["scenes", "fetch", "--nope"],
                 ["metric", "nope", "a.png", "b.png"]):
        with pytest.raises(SystemExit) as exc:  # argparse's own usage errors: 2 as well
            main(argv)
        assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        export_main(["--adopt", "x.onnx"])
    assert exc.value.code == 2


def test_capture_never_runs_a_whole_split_by_default(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["capture", "--per-scene", "1", "--out", str(tmp_path / "x")]) == 2
    assert "--split NAME" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_info_on_a_foreign_model_speaks_in_flags(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from .conftest import build_onnx

    path = build_onnx(tmp_path / "foreign.onnx", weights=np.zeros((4, 4), np.float32), metadata=None)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert "--metadata SIDECAR.yaml" in err and "metadata=" not in err


def test_info_on_a_foreign_model_without_onnx_installed(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The runtime install has no onnx: `rtp info` of a model without metadata said "this needs onnx, which is not
    installed" (the missing-metadata hint read the file with onnx), not how to give the model its sidecar. Broken
    metadata is still said as broken."""
    import onnx

    from .conftest import build_onnx

    path = build_onnx(tmp_path / "foreign.onnx", weights=np.zeros((4, 4), np.float32), metadata=None)
    broken = onnx.load(path)
    onnx.helper.set_model_props(broken, {sdk.METADATA_KEY: '{"metric": "jnyang", "tile_si'})
    onnx.save(broken, tmp_path / "broken.onnx")
    monkeypatch.setitem(sys.modules, "onnx", None)  # (import onnx: ModuleNotFoundError, as on the runtime install)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert "carries no rtp metadata: pass --metadata SIDECAR.yaml" in err and "not installed" not in err, err
    assert main(["info", str(tmp_path / "broken.onnx")]) == 2
    err = capsys.readouterr().err
    assert "not valid JSON" in err and "carries no rtp metadata" not in err, err


def test_info_on_a_published_model_says_it_adopts_without_a_sidecar(capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp info JNYang.onnx`, the paper's published file, told the user to write a sidecar; rtp ships one for each
    published model (docs/export.md "Published models"), and `rtp-export --adopt` bakes it in."""
    published = Path(__file__).parent / "data" / "published" / "JNYang.onnx"
    assert main(["info", str(published)]) == 2
    err = capsys.readouterr().err
    assert "published jnyang model" in err and f"rtp-export --adopt {published} -o OUT.onnx" in err, err
    assert "--metadata SIDECAR.yaml" not in err


def test_adapters_check_of_a_model_without_metadata_names_no_flag_it_lacks(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp adapters check --model FOREIGN.onnx` passed on the SDK's hint, "pass its sidecar (sdk.load(...,
    metadata=), the commands' --metadata SIDECAR.yaml)": the command has no --metadata, and the paper's published
    files need no sidecar at all. It says how to adopt the model and give the adopted file to --model instead."""
    from .conftest import build_onnx

    foreign = build_onnx(tmp_path / "foreign.onnx", weights=np.zeros((4, 4), np.float32), metadata=None)
    published = Path(__file__).parent / "data" / "published" / "JNYang.onnx"
    for model in (foreign, published):
        assert main(["adapters", "check", "moderngl", "--model", str(model)]) == 2
        err = capsys.readouterr().err
        assert f"{model} carries no rtp metadata" in err and "then --model OUT.onnx" in err, err
        assert "pass --metadata" not in err and "metadata=" not in err and "the commands' --metadata" not in err, err
    assert f"rtp-export --adopt {published} -o OUT.onnx" in err and "SIDECAR" not in err, err


def test_info_on_broken_metadata_says_what_is_broken(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Metadata that is there but not JSON is not "no rtp metadata": the hint to bake a sidecar in would send
    the user to `rtp-export --adopt`, which refuses a file that already carries the key."""
    import onnx

    from .conftest import build_onnx

    path = build_onnx(tmp_path / "m.onnx", weights=np.zeros((4, 4), np.float32), metadata=None)
    model = onnx.load(path)
    onnx.helper.set_model_props(model, {sdk.METADATA_KEY: '{"metric": "jnyang", "tile_si'})
    onnx.save(model, path)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert "not valid JSON" in err and "carries no rtp metadata" not in err


def test_exit_code_of_non_rtp_errors() -> None:
    assert sdk.exit_code(KeyboardInterrupt()) == 130
    assert sdk.exit_code(RuntimeError()) == sdk.EXIT_FAILED == 1
    assert sdk.exit_code(sdk.InferenceError("x")) == 1 and sdk.exit_code(sdk.ParameterError("x")) == sdk.EXIT_USAGE

    class ThirdParty(sdk.MetadataError):
        """A subclass outside rtp inherits its parent's code."""

    assert sdk.exit_code(ThirdParty("x")) == 2


# -- the choices come from the shared facts -------------------------------------------------

def _parse(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(list(argv))


def test_metric_tile_and_output_choices_are_the_sdks() -> None:
    assert _option(("targets",), "metrics").default == ",".join(sdk.TARGET_METRICS)
    assert _parse("targets", "d").metrics == sdk.TARGET_METRICS
    assert _parse("targets", "d", "--metrics", ",".join(sdk.METRICS)).metrics == tuple(sdk.METRICS)
    # a metric is rtp's own or a plugin's (looked up when the command runs): each of rtp's own is taken and named
    for command, flag in ((("train",), "metric"), (("metric",), "metric"), (("play",), "fail_metric")):
        option = _option(command, flag)
        assert all(option.type(m) == m for m in sdk.METRICS), command  # type: ignore[misc,operator]
        assert ", ".join(sdk.METRICS) in (option.help or ""), command
    assert tuple(_option(("train",), "tile").choices or ()) == sdk.TILE_SIZES
    assert tuple(_option(("metric",), "tile").choices or ()) == sdk.TILE_SIZES
    assert _option(("metric",), "tile").default == sdk.DEFAULT_TILE_SIZE
    base = ("train", "--data", "d", "--metric", next(iter(sdk.METRICS)), "--out", "o.pt")
    for outputs in sdk.OUTPUT_SETS:
        assert _parse(*base, "--outputs", ",".join(outputs)).outputs == outputs
    assert _parse(*base, "--inputs", ",".join(sdk.DEFAULT_INPUTS)).inputs == sdk.DEFAULT_INPUTS
    # the tile flag of play, demo and evaluate is taken where the tile is --tile
    assert _parse(*base, "--tile-size", "8").tile == 8 and _parse("metric", "flip", "a", "b", "--tile-size", "8").tile == 8
    assert ",".join(sdk.DEFAULT_OUTPUTS) in (_option(("train",), "outputs").help or "")
    for bad in (("targets", "d", "--metrics", "nope"), ("targets", "d", "--metrics", ","), ("metric", "flp", "a", "b"),
                (*base[:4], "jnyan", *base[5:]), (*base, "--outputs", ",".join(reversed(sdk.DEFAULT_OUTPUTS))),
                (*base, "--inputs", "nope"), (*base, "--tile", "3"), ("metric", "flip", "a", "b", "--tile", "3")):
        with pytest.raises(SystemExit) as exc:
            _parse(*bad)
        assert exc.value.code == 2, bad


def test_split_profile_and_transform_choices_are_their_rooms() -> None:
    from rtp import metrics
    from rtp.capture.scenes import SPLIT_NAMES
    from rtp.capture.viewpoints import DEFAULT_PROFILES, MOTION_PROFILES

    assert tuple(_option(("capture",), "split").choices or ()) == tuple(SPLIT_NAMES)
    assert _parse("capture", "--per-scene", "1", "--out", "o").profiles == DEFAULT_PROFILES
    assert set(DEFAULT_PROFILES) < set(MOTION_PROFILES)
    # (None: not given, so that a metric list without JNFLIP or JNYang can refuse one given; the default is the room's)
    assert _option(("targets",), "weber_l").default is None
    assert f"(default: {metrics.DEFAULT_WEBER_L:g})" in (_option(("targets",), "weber_l").help or "")
    transforms = tuple(_option(("train",), "transform").choices or ())
    assert transforms and "linear" not in transforms  # training fits mu_y; linear is for adopted models
    for t in transforms:
        assert getattr(sdk.Transform, t)(mu_y=0.1).type == t


def test_head_choices_are_the_networks() -> None:
    from rtp.train.model import ARCHS, HEADS

    assert tuple(_option(("train",), "head").choices or ()) == HEADS
    assert tuple(_option(("train",), "arch").choices or ()) == tuple(ARCHS)


def test_cli_keeps_no_lists_of_metrics_tiles_or_rates() -> None:
    """No tuple or list literal in cli/ holds two or more metric names, rate names or tile sizes: they
    come from rtp.sdk (a single name, such as the demo's default model, is not a list)."""
    names = set(sdk.METRICS) | set(sdk.ALL_RATES)
    bad = []
    for path in sorted((ROOT / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                values = [e.value for e in node.elts if isinstance(e, ast.Constant)]
                if (sum(v in names for v in values if isinstance(v, str)) >= 2
                        or sum(v in sdk.TILE_SIZES for v in values if isinstance(v, int) and v > 2) >= 2):
                    bad.append(f"{path.name}:{node.lineno}")
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.count(",") >= 1:
                if sum(part.strip() in names for part in node.value.split(",")) >= 2:
                    bad.append(f"{path.name}:{node.lineno}")
    assert not bad, f"literal lists of metrics, rates or tile sizes in cli/: {bad}"


def test_a_job_that_fails_before_any_progress_erases_its_empty_bar() -> None:
    """`rtp play nomap` used to leave "play nomap: 0%| 0/10" above its error; the bar of a job that fails
    before its first step is not left on the terminal, one that fails later is (it shows how far it got)."""
    import io

    from rtp.cli._run import Bar

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    args = argparse.Namespace(quiet=False, no_progress=False)
    for terminal, steps, leaves in ((True, 0, False), (True, 3, True), (False, 0, True), (False, 3, True)):
        # (a file or a pipe cannot erase the bar: it ends the bar's line, the error then has its own)
        with pytest.raises(sdk.ParameterError), Bar(args, 10, "play nomap", "frame") as bar:
            bar._bar.fp = Terminal() if terminal else io.StringIO()
            bar.update_to(steps)
            raise sdk.ParameterError("map 'nomap' is not listed", "scene")
        assert bar._bar.leave is leaves
    with Bar(args, 10, "play", "frame") as bar:  # a job that ends well keeps its bar
        bar._bar.fp = Terminal()
    assert bar._bar.leave is True


def test_a_long_first_step_says_what_it_does(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp capture --per-scene 100000` planned its viewpoints for minutes before the bar moved (or
    showed at all): the bar says what it plans meanwhile, and stops saying it once samples come."""
    import io

    from rtp.cli._run import Bar

    args = argparse.Namespace(quiet=False, no_progress=False)
    capsys.readouterr()
    with Bar(args, 10, "capture", "sample") as bar:
        bar.status("planning a/slow's viewpoints: 1/10")  # before the bar's delay: not drawn
        assert capsys.readouterr().err == ""
        bar._bar.start_t -= Bar.DELAY
        bar.status("planning a/slow's viewpoints: 2/10")
        assert capsys.readouterr().err.endswith("planning a/slow's viewpoints: 2/10]")
        bar.update_to(1)  # the count moves: the text goes
        assert "planning" not in capsys.readouterr().err.rsplit("\r", 1)[-1]
    # Stopped while it planned (Ctrl-C): the bar it drew is ended (a pipe, a log) or erased (a
    # terminal) before the error's line, as a bar that counted would be. (Drawn by status() alone,
    # tqdm took it for never shown and left "...planning ...: 3/10]rtp capture: interrupted".)
    monkeypatch.setattr(Bar, "DELAY", 0.05)
    for terminal, end in ((False, "\n"), (True, "\r")):
        fp = type("Terminal", (io.StringIO,), {"isatty": lambda self: True})() if terminal else io.StringIO()
        with pytest.raises(KeyboardInterrupt), Bar(args, 10, "capture", "sample") as bar:
            bar._bar.fp = fp  # (where tqdm's close writes its last character)
            time.sleep(0.06)  # (past the bar's delay, as a long plan is)
            bar.status("planning a/slow's viewpoints: 3/10")
            raise KeyboardInterrupt
        assert "3/10" in capsys.readouterr().err and fp.getvalue() == end, terminal
    monkeypatch.setattr(Bar, "DELAY", 0.0)
    assert main(["capture", "--scene", "procedural:1", "--per-scene", "2", "--size", "64x48", "--profiles", "slow",
                 "--out", str(tmp_path / "data")]) == 0
    err = capsys.readouterr().err
    assert "planning procedural:1/slow's viewpoints: 1/2]" in err
    last = err.rsplit("\r", 1)[-1]
    assert "2/2 [" in last and "planning" not in last, err


def test_a_step_that_comes_too_soon_to_draw_is_drawn_when_it_may_be(capsys: pytest.CaptureFixture[str],
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp play`'s steps before its first frame come in quick succession, the last of them for
    seconds: a status held back by the bar's delay or its rate is drawn by a timer once it may be, if
    it is still the one to show; never after the bar is closed."""
    from rtp.cli._run import Bar

    args = argparse.Namespace(quiet=False, no_progress=False)
    monkeypatch.setattr(Bar, "DELAY", 0.1)
    capsys.readouterr()
    with Bar(args, 10, "play", "frame") as bar:
        bar.status("slow: loading a")
        bar.status("slow: the first frame")  # both before the delay: neither drawn yet
        assert capsys.readouterr().err == ""
        time.sleep(0.4)
        err = capsys.readouterr().err.rstrip()  # (a shorter line is padded over the last)
        assert err.endswith("slow: the first frame]") and "loading" not in err, err
        bar.status("slow: writing play_slow.gif")  # drawn at once (past the delay, not drawn for 0.3 s)
        bar.status("writing the report")  # within STATUS_EVERY: held back, then drawn by the timer
        assert capsys.readouterr().err.rstrip().endswith("play_slow.gif]")
        time.sleep(0.3)
        assert capsys.readouterr().err.rstrip().endswith("writing the report]")
        bar.update_to(10)
    assert "writing" not in capsys.readouterr().err.rsplit("\r", 1)[-1]  # a job that ended well ends on its count
    import threading

    with Bar(args, 10, "play", "frame") as bar:
        bar.status("slow: loading a")
    time.sleep(0.03)  # (a cancelled timer's thread ends at once; one left running would wait out the delay)
    assert not [t for t in threading.enumerate() if isinstance(t, threading.Timer)]
    time.sleep(0.2)
    assert "loading" not in capsys.readouterr().err  # closed before its delay: nothing drawn after


def test_play_says_what_it_does_between_its_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp play` at 1280x720 sat at 0/N for about 11 s (the map, its camera path, the renderer, the
    first frame at every rate) and at N/N for seconds (the GIF, the report and plots): the bar says
    which step runs, and ends on its count."""
    from rtp.cli._run import Bar

    monkeypatch.setattr(Bar, "DELAY", 0.0)
    monkeypatch.setattr(Bar, "STATUS_EVERY", 0.0)
    capsys.readouterr()
    assert main(["play", "procedural:0", "--path", "fast", "--frames", "3", "--size", "64x48", "--methods", "full",
                 "--no-sweep", "--flip-every", "0", "--out", str(tmp_path / "play")]) == 0
    err = capsys.readouterr().err
    steps = ["0/3 [", "fast: loading procedural:0]", "fast: planning the camera path]", "fast: starting the renderer]",
             "fast: the first frame", "3/3 [", "fast: writing play_fast.gif]", "writing the report and its plots]"]
    at = [err.find(s) for s in steps]
    assert -1 not in at and at == sorted(at), (at, err)
    last = err.rsplit("\r", 1)[-1]
    assert "3/3 [" in last and "writing" not in last, err


def test_play_in_workers_shows_each_paths_step_while_another_counts_frames(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """With --workers the paths run side by side: the bar showed only the latest step of either, and
    the other path's frames erased a step that lasts (one path writing its GIF while the other plays).
    Now it shows the step of every path not playing frames, kept while the count moves."""
    import types

    import rtp.evaluate
    from rtp.cli._run import Bar

    monkeypatch.setattr(Bar, "DELAY", 0.0)
    monkeypatch.setattr(Bar, "STATUS_EVERY", 0.0)

    def fake_play(*_: Any, progress: Callable[[int], None], stage: Callable[[str], None], **__: Any) -> Any:
        stage("slow: loading a")
        stage("fast: loading a")
        stage("slow: playing")
        progress(1)
        stage("fast: playing")
        progress(1)
        stage("fast: writing play_fast.gif")
        time.sleep(0.15)  # (past tqdm's mininterval: the count's move is drawn)
        progress(1)  # slow's frames count on while fast writes its GIF
        stage("fast: done")
        progress(1)
        stage("slow: done")
        stage("writing the report")
        return types.SimpleNamespace(to_markdown=lambda: "report", files=["play.md"])

    monkeypatch.setattr(rtp.evaluate, "play", fake_play)
    capsys.readouterr()
    assert main(["play", "procedural:0", "--frames", "2", "--workers", "2", "--out", str(tmp_path / "p")]) == 0
    drawn = [d.rstrip() for d in capsys.readouterr().err.split("\r") if d.strip()]
    want = [("0/4 [", "slow: loading a · fast: loading a]"), ("0/4 [", "| 0/4 [00:00<?, ?frame/s, fast: loading a]"),
            ("2/4 [", "fast: writing play_fast.gif]"), ("3/4 [", "fast: writing play_fast.gif]"),
            ("4/4 [", "writing the report]")]
    k = 0
    for count, end in want:  # drawn in this order
        k = next((j for j in range(k, len(drawn)) if count in drawn[j] and drawn[j].endswith(end)), -1)
        assert k >= 0, (count, end, drawn)
    assert drawn[-1].endswith("frame/s]") and "writing" not in drawn[-1], drawn  # it ends on its count


def test_verbose_progress_is_logged_whole_and_repeated_warnings_once(capsys: pytest.CaptureFixture[str]) -> None:
    """-v logs progress: every INFO line (a validation step of `rtp -v train`, each job's planning
    time), none collapsed as repeats (only the first of each template was shown); a warning repeated
    with other values shows once, then a count at the end."""
    import logging

    from rtp.cli._run import run

    log = logging.getLogger("rtp.train")

    def body(args: argparse.Namespace) -> int:
        for step in (100, 200, 300):
            log.info("step %d: val R2 %.3f", step, step / 1000)
        for sid in ("a", "b", "c"):
            log.warning("sample %s has no targets", sid)
        return 0

    for verbose in (True, False):
        assert run("rtp train", argparse.Namespace(verbose=verbose, quiet=False, no_progress=True), body) == 0
        err = capsys.readouterr().err
        steps = [f"INFO rtp.train: step {n}: val R2 {n / 1000:.3f}" for n in (100, 200, 300)]
        assert all((line in err) == verbose for line in steps), err
        assert err.count("has no targets") == 2 and "WARNING rtp.train: sample a has no targets" in err
        assert "WARNING (repeated): 2 more like: sample a has no targets" in err


def test_logging_keeps_its_filters_and_stderr_whatever_tqdms_redirection(monkeypatch: pytest.MonkeyPatch,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The log is on stderr, collapsed, at the level the options ask, with any tqdm pyproject allows: tqdm
    4.60's logging_redirect_tqdm (reproduced here) swapped rtp's handler for one that wrote to stdout,
    into `rtp info --json`'s JSON, and kept none of its filters (repeats not collapsed). A library logger
    with a level of its own (INFO) passed its warnings through -q."""
    import logging
    import sys as _sys

    import tqdm.contrib.logging

    from rtp.cli._run import run

    @contextlib.contextmanager
    def redirect_of_tqdm_4_60(loggers: list[logging.Logger] | None = None, **_: Any) -> Any:
        def emit(self: logging.Handler, record: logging.LogRecord) -> None:
            print(self.format(record), file=_sys.stdout)  # (tqdm.write's default file)

        for logger in loggers or [logging.root]:
            old = logger.handlers
            console = [h for h in old if isinstance(h, logging.StreamHandler) and h.stream in (_sys.stdout, _sys.stderr)]
            handler = type("_TqdmLoggingHandler", (logging.StreamHandler,), {"emit": emit})()
            handler.setFormatter(console[0].formatter if console else None)
            logger.handlers = [h for h in old if h not in console] + [handler]
            try:
                yield
            finally:
                logger.handlers = old

    monkeypatch.setattr(tqdm.contrib.logging, "logging_redirect_tqdm", redirect_of_tqdm_4_60)
    chatty = logging.getLogger("some.library")
    monkeypatch.setattr(chatty, "level", logging.INFO)

    def body(args: argparse.Namespace) -> int:
        for sid in ("a", "b", "c"):
            logging.getLogger("rtp.capture").warning("sample %s has no targets", sid)
        chatty.warning("a library's warning")
        return 0

    assert run("rtp info", argparse.Namespace(verbose=0, quiet=False, no_progress=True), body) == 0
    out, err = capsys.readouterr()
    assert out == "", out
    assert err.count("has no targets") == 2 and "2 more like: sample a has no targets" in err, err
    assert "a library's warning" in err
    assert run("rtp info", argparse.Namespace(verbose=0, quiet=True, no_progress=True), body) == 0
    out, err = capsys.readouterr()
    assert out == "" and "a library's warning" not in err and "WARNING rtp" not in err, (out, err)


def test_a_job_that_fails_at_once_leaves_only_its_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp evaluate nomodel` printed "evaluate nomodel: 0sample [00:00, ?sample/s]\\r   \\r" in front of
    its error in a log: a bar shows only after Bar.DELAY seconds."""
    assert main(["evaluate", str(tmp_path / "nomodel.onnx"), "--data", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rtp evaluate: error:") and err.count("\n") == 1, err


def test_a_log_line_before_the_bar_shows_neither_draws_it_nor_leaves_it(capsys: pytest.CaptureFixture[str],
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp train` on a dataset without its validation maps warned in its first half second: tqdm.write drew the
    bar at once (within its delay), put "\\r\\r" before the warning in a log, and the bar, taken by tqdm for never
    shown, was not ended on close, so the error came after its text: "3/3 [00:00, loss=0.0814]rtp train: error:
    dead output(s) ...". A log line clears and redraws only a bar that is on screen."""
    import logging

    from rtp.cli._run import Bar, run

    log = logging.getLogger("rtp.train")
    args = argparse.Namespace(verbose=0, quiet=False, no_progress=False)

    def body(a: argparse.Namespace) -> int:
        with Bar(a, 3, "train", "step") as bar:
            log.warning("d1 holds none of the validation maps")
            bar.update_to(3)
        raise sdk.ParameterError("dead output(s) 1x2", "outputs")

    capsys.readouterr()
    assert run("rtp train", args, body) == 2
    err = capsys.readouterr().err
    assert err == ("WARNING rtp.train: d1 holds none of the validation maps\n"
                   "rtp train: error: dead output(s) 1x2\n"), err
    # a bar on screen is cleared before the line and drawn again after it, and ends its own line on close
    monkeypatch.setattr(Bar, "DELAY", 0.0)

    def shown(a: argparse.Namespace) -> int:
        with Bar(a, 3, "train", "step") as bar:
            bar.update_to(1)
            log.warning("a warning while it counts")
            bar.update_to(3)
        return 0

    assert run("rtp train", args, shown) == 0
    err = capsys.readouterr().err
    before, after = err.split("WARNING rtp.train: a warning while it counts\n")
    assert before.startswith("\rtrain:") and before.endswith("\r"), err
    assert after.startswith("\rtrain:") and after.endswith("]\n") and "3/3" in after.rsplit("\r", 1)[-1], err


def test_the_error_is_the_last_line_after_the_repeats_count(capsys: pytest.CaptureFixture[str]) -> None:
    """A job that warned of many samples and then failed printed its error, then "WARNING (repeated): 2 more
    like: ...": the error (or the interruption) was not the last line of its stderr. The count comes first."""
    import logging

    from rtp.cli._run import run

    def body(error: BaseException) -> Callable[[argparse.Namespace], int]:
        def warn_then_fail(args: argparse.Namespace) -> int:
            for sid in ("a", "b", "c"):
                logging.getLogger("rtp.capture").warning("sample %s has no targets", sid)
            raise error
        return warn_then_fail

    args = argparse.Namespace(verbose=0, quiet=False, no_progress=True)
    for error, code, last in ((sdk.ParameterError("--ppd must be a number", "ppd"), 2, "rtp targets: error: --ppd"),
                              (KeyboardInterrupt(), 130, "rtp targets: interrupted")):
        capsys.readouterr()
        assert run("rtp targets", args, body(error)) == code
        lines = capsys.readouterr().err.splitlines()
        assert lines[-2:-1] == ["WARNING (repeated): 2 more like: sample a has no targets"], lines
        assert lines[-1].startswith(last) and len(lines) == 3, lines


#: The consoles rtp's output must survive: an engine's or CI's C/POSIX locale (Python's UTF-8 mode off), a pipe
#: told ASCII, a Windows console's cp1252; and UTF-8, where every character stays as it is.
CONSOLES = {"C": ({"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}, "ascii"),
            "ascii": ({"PYTHONIOENCODING": "ascii"}, "ascii"), "cp1252": ({"PYTHONIOENCODING": "cp1252"}, "cp1252"),
            "utf-8": ({"PYTHONIOENCODING": "utf-8"}, "utf-8")}


def _rtp(argv: Sequence[str], env: dict[str, str] | None = None, **kw: Any) -> subprocess.CompletedProcess[bytes]:
    """``python -m rtp ARGV`` as a user's shell runs it (output buffered: no PYTHONUNBUFFERED), in ``env``."""
    import os

    base = {k: v for k, v in os.environ.items()
            if k not in ("PYTHONIOENCODING", "PYTHONUTF8", "PYTHONUNBUFFERED", "LC_ALL", "LC_CTYPE", "LANG")}
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.run([sys.executable, "-m", "rtp", *argv], env={**base, "COLUMNS": "200", **(env or {})},
                          timeout=300, **kw)


@pytest.mark.parametrize("console", sorted(CONSOLES))
def test_output_on_a_console_that_is_not_utf8(console: str, tiny_model: Callable[..., Path]) -> None:
    """Under LC_ALL=C (or PYTHONIOENCODING=ascii) `rtp evaluate` and `rtp train` crashed with a UnicodeEncodeError at
    their last line, its "R²" (`rtp train -h` too, at "what R² scores"), after the whole job; cp1252 at the table's
    "σ MAE". What the console cannot encode is written in ASCII ("R^2", "sigma", "<="), else as its escape; a
    UTF-8 console, and a cp1252 one for what it holds, keep every character."""
    env, encoding = CONSOLES[console]
    path = tiny_model(base_metadata(description="R² 95% · σ 0.1 ≤ 0.2, café"))
    info = _rtp(["info", str(path)], env)
    assert info.returncode == 0 and not info.stderr, info.stderr.decode(errors="replace")[-2000:]
    line = next(x for x in info.stdout.decode(encoding).splitlines() if x.startswith("description"))
    want = {"ascii": r"R^2 95% * sigma 0.1 <= 0.2, caf\xe9", "cp1252": "R² 95% · sigma 0.1 <= 0.2, café",
            "utf-8": "R² 95% · σ 0.1 ≤ 0.2, café"}[encoding]
    assert line.endswith("  " + want), line
    helped = _rtp(["train", "-h"], env)
    assert helped.returncode == 0 and not helped.stderr, helped.stderr.decode(errors="replace")[-2000:]
    assert f"(what R{'^2' if encoding == 'ascii' else '²'} scores)" in helped.stdout.decode(encoding)


def test_the_console_handlers_are_put_back(tiny_model: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """In-process, main() writes through its own error handler and leaves a caller's streams as they were."""
    import io

    raw = io.BytesIO()
    out = io.TextIOWrapper(raw, encoding="ascii", errors="strict", write_through=True)
    path = tiny_model(base_metadata(description="R² σ"))
    old = sys.stdout
    sys.stdout = out
    try:
        assert main(["info", str(path)]) == 0
    finally:
        sys.stdout = old
    assert out.errors == "strict"
    assert b"R^2 sigma" in raw.getvalue(), raw.getvalue()


@pytest.mark.parametrize("argv", [["--version"], ["weights", "list"], ["scenes", "list"], ["info", "nope"],
                                  ["info", "--bogus"]], ids=" ".join)
def test_a_closed_pipe_ends_the_command_quietly(argv: list[str], tmp_path: Path) -> None:
    """`rtp ... | head -1` where head has gone: Python's flush at exit said "Exception ignored ... BrokenPipeError"
    and exited 120 (buffered output: any shell's, without PYTHONUNBUFFERED), and with stderr in the pipe too (`2>&1`)
    the error's own line failed the same way, so `rtp info nope` exited 120, not 2. The command's exit code stays,
    and nothing is said about the pipe."""
    import os

    code = {"info nope": 2, "info --bogus": 2}.get(" ".join(argv), 0)
    read, write = os.pipe()
    os.close(read)
    try:
        said = _rtp(argv, stdout=write, stderr=subprocess.PIPE)  # stdout's reader gone
        both = _rtp(argv, stdout=write, stderr=write)  # and stderr's
    finally:
        os.close(write)
    assert said.returncode == code and "BrokenPipe" not in said.stderr.decode(), said.stderr.decode()[-2000:]
    assert both.returncode == code


def test_the_console_handler_keeps_the_streams_own_for_the_rest() -> None:
    """Under a C locale stdout's handler is surrogateescape: a path's raw bytes (decoded as surrogates) are written
    back as they were, rtp's own characters in ASCII and anything else as its escape, in any mix."""
    from rtp.cli._run import _error_handler

    text = "R²σ \udcff\udcfe é×≤"
    assert text.encode("ascii", _error_handler("surrogateescape")) == b"R^2sigma \xff\xfe \\xe9x<="
    assert text.encode("ascii", _error_handler("strict")) == b"R^2sigma \\udcff\\udcfe \\xe9x<="
    assert text.encode("cp1252", _error_handler("strict")) == "R²sigma \\udcff\\udcfe é×<=".encode("cp1252")


def test_a_quoted_tilde_in_every_path_option_is_the_home_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A `~` the shell did not expand (quoted, `--out '~/data'`, or pasted from a config) made a folder literally
    named `~` in the current folder (`rtp scenes fetch --cache-dir '~/scenes'` unpacked 400 MB there), while
    $RTP_SCENE_CACHE and $RTP_WEIGHTS_CACHE read the same text as the home folder. Every path option of every command
    (each --cache-dir, --out, --data, DATA, --splits, --metadata, rtp-export's) now takes a leading `~` as the home
    folder; nothing named `~` is made here. So do the options that take a name or a path (--model, MODEL, a scene,
    --recipe, --teachers, play's --methods: each item of a list), a name as typed; an option whose help names a file
    kind (.onnx, .glb, YAML) without such a type fails here."""
    from rtp.cli._main import (
        _checked_path,
        _folders_csv,
        _in_file,
        _name_or_path,
        _names_or_paths,
        _path_text,
        out_animation,
        out_image,
    )

    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    path_types = {_path_text, _in_file, out_image, out_animation, _folders_csv}
    # (the options that take a name or a path: --model, a scene, --recipe, --teachers, play's --methods; a name never
    # starts with ~, so one that does is a path, and a name is kept as typed)
    name_or_path_types = {_name_or_path, _names_or_paths}
    file_kinds = re.compile(r"\.onnx|\.glb|\.gltf|\.ya?ml\b|YAML")  # (what a help says an option may name)
    seen: set[str] = set()
    for _entry, build in ENTRY.values():
        for command in _commands(build()):
            for action in _subparser(build(), command)._actions:
                kind = getattr(action.type, "__name__", "")
                if action.type in path_types or action.type in name_or_path_types or kind in ("_out_folder", "_out_file"):
                    text = "~/sub/x.gif" if action.type in (out_image, out_animation) else "~/sub/x"
                    assert action.type(text) == str(home / "sub" / text[6:]), (command, action.dest)  # type: ignore[misc,operator]
                    seen.add(action.dest)
                    if action.type in name_or_path_types:
                        for name in ("jnyang", "procedural:3", "shipped", "jnyang@4:features"):
                            assert action.type(name) == name, (command, action.dest)  # type: ignore[misc,operator]
                elif action.dest in ("cache_dir", "out", "output", "data", "data_flag", "splits", "metadata", "model",
                                     "scene", "config", "example_scene", "teachers", "methods") and command not in (
                                         ("import",), ("evaluate",)):  # (their --scene: a level's name, no file)
                    raise AssertionError(f"{command} --{action.dest} takes no path type, so no ~ either")
                elif file_kinds.search(action.help or ""):
                    raise AssertionError(f"{command} {action.dest}: its help names a file it may be, so it takes a "
                                         "leading ~ as the home folder: give it a path or name-or-path type")
    assert {"cache_dir", "out", "output", "data", "data_flag", "splits", "metadata", "frames", "model", "scene",
            "config", "example_scene", "teachers", "methods"} <= seen
    assert _names_or_paths("~/a.glb, procedural:1,~/b.obj") == f"{home / 'a.glb'}, procedural:1,{home / 'b.obj'}"
    assert _names_or_paths("~/m.onnx@4:features,yang2019") == f"{home / 'm.onnx'}@4:features,yang2019"
    (home / "a,~").mkdir()  # (an existing file's path is one scene, commas and all, ~ and all)
    (home / "a,~" / "b.glb").write_text("")
    assert _names_or_paths("~/a,~/b.glb") == str(home / "a,~" / "b.glb") and _name_or_path("a~b") == "a~b"
    assert _folders_csv("~/a, b,~/c") == f"{home / 'a'}, b,{home / 'c'}"  # (rtp train --data's list, each folder)
    assert _checked_path("~", folder=True) == str(home)
    for text in ("~a\x00", "~\x00/x"):  # (a ValueError out of the ~user lookup: "invalid _out_folder value")
        with pytest.raises(argparse.ArgumentTypeError, match="expected a path"):
            _checked_path(text, folder=True)
        assert _name_or_path(text) == text  # (the loader says what it is not)
    assert _path_text("a~b") == "a~b" and _path_text("./~") == "./~"  # (only a leading ~ is the home folder)
    assert not (tmp_path / "~").exists()


def _tilde_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    return home


def test_a_quoted_tilde_model_path_is_read_from_the_home_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp info '~/m.onnx'` (and --model, rtp evaluate's MODEL, play's --methods) looked for a file in a folder
    named `~` of the current folder, then said "no model file at '~/m.onnx'"; a name never starts with `~`, so such a
    value is the home folder's file. One that is not there is named expanded."""
    import json
    import shutil

    home = _tilde_home(tmp_path, monkeypatch)
    shutil.copy(ROOT / "models" / "jnyang.onnx", home / "m.onnx")
    assert main(["info", "~/m.onnx", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["path"] == str(home / "m.onnx")
    assert main(["info", "~/nope.onnx"]) == 2
    assert f"no model file at '{home / 'nope.onnx'}'" in capsys.readouterr().err
    assert main(["play", "procedural:0", "--methods", "full,~/nope.onnx@4", "--frames", "3", "--out", "p", "-q"]) == 2
    assert f"no model file at '{home / 'nope.onnx'}'" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_a_quoted_tilde_scene_file_is_read_from_the_home_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Every option that takes a scene (a name, procedural:N, or a file) read `'~/level.obj'` as a folder `~` of the
    current folder: "mesh file not found", "no such file". Now each reads the home folder's file (here one with no
    triangles, which each says of the expanded path), as capture's comma list does for each of its items."""
    home = _tilde_home(tmp_path, monkeypatch)
    (home / "lines.obj").write_text("v 0 0 0\nv 1 0 0\nl 1 2\n")
    small = ["--size", "64x48", "-q"]
    for argv in (["demo", "--scene", "~/lines.obj", "--out", "o", *small],
                 ["play", "~/lines.obj", "--frames", "3", "--methods", "full", "--out", "o", *small],
                 ["capture", "--scene", "procedural:1,~/lines.obj", "--per-scene", "1", "--out", "o", *small],
                 ["import", "frames", "--write-example", "--example-scene", "~/lines.obj", "--frames", "1", *small]):
        assert main(argv) == 2, argv
        assert f"{home / 'lines.obj'} contains no triangles" in capsys.readouterr().err, argv
        assert not (tmp_path / "o").exists() and not (tmp_path / "frames").exists(), argv
    assert main(["play", "~/missing.glb", "--frames", "3", "--out", "o", *small]) == 2
    assert str(home / "missing.glb") in capsys.readouterr().err


def test_a_quoted_tilde_recipe_is_read_from_the_home_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp train --recipe '~/r.yaml'` said "recipe '~/r.yaml': no such file (or pass the name of one that ships with
    rtp ...)" of a file that is there; now the home folder's recipe is read (here one whose steps do not fit)."""
    home = _tilde_home(tmp_path, monkeypatch)
    (home / "r.yaml").write_text("steps: -5\n")
    train = ["train", "--data", "data", "--metric", "jnyang", "--out", "m.pt", "-q"]
    assert main([*train, "--recipe", "~/r.yaml"]) == 2
    assert f"recipe {home / 'r.yaml'} sets steps: -5" in capsys.readouterr().err
    assert main([*train, "--config", "~/nope.yaml"]) == 2
    assert f"recipe '{home / 'nope.yaml'}': no such file" in capsys.readouterr().err
    assert not (tmp_path / "m.pt").exists()
