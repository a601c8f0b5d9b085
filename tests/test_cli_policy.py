"""The command line's one policy: every subcommand's help exits 0 and shows its defaults, the same
error class gives the same exit code in every entry point, and --version works everywhere."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from rtp import sdk
from rtp.cli import build_export_parser, build_parser, export_main, main


def _commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command path of a parser, found from the parser itself: (), ("info",), ("scenes", "fetch"), ..."""
    out = [prefix]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _commands(sub, (*prefix, name))
    return out


COMMANDS = _commands(build_parser())


def test_the_parser_has_every_command() -> None:
    assert {c[0] for c in COMMANDS if c} >= {"info", "scenes", "capture", "preview", "targets", "train", "evaluate",
                                             "demo", "metric"}
    assert ("scenes", "fetch") in COMMANDS and ("scenes", "list") in COMMANDS


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "rtp")
def test_help_exits_0_and_shows_defaults(command: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main([*command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "usage: rtp" in text
    parser = build_parser()
    for name in command:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    for action in parser._actions:
        shown = action.default not in (None, False, argparse.SUPPRESS) and action.option_strings and not action.required
        if shown and action.help and "default" not in action.help:
            assert f"(default: {action.default}" in " ".join(text.split()), (command, action.dest)


def test_rtp_export_help_and_versions(capsys: pytest.CaptureFixture[str]) -> None:
    for entry, prog in ((export_main, "rtp-export"), (main, "rtp")):
        with pytest.raises(SystemExit) as exc:
            entry(["--version"])
        assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"{prog} {sdk.__version__}"
    with pytest.raises(SystemExit) as exc:
        export_main(["--help"])
    assert exc.value.code == 0 and "(default:" in capsys.readouterr().out
    assert build_export_parser().prog == "rtp-export"


def test_common_options_go_before_or_after_the_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["-q", "info", "nope.onnx"], ["info", "nope.onnx", "-q"], ["info", "-v", "nope.onnx"]):
        assert main(argv) == 2
    assert "Traceback" in capsys.readouterr().err  # -v shows it


def test_one_error_class_one_exit_code_in_every_entry_point(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = str(tmp_path / "nope.onnx")
    assert main(["info", missing]) == sdk.ModelNotFoundError.exit_code == 2
    assert main(["evaluate", missing, "--data", str(tmp_path)]) == 2
    assert export_main([str(tmp_path / "nope.pt")]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 3 and "rtp info: error:" in err and "rtp-export: error:" in err
    with pytest.raises(SystemExit) as exc:  # argparse's own usage errors: 2 as well
        main(["capture", "--per-scene", "0", "--out", str(tmp_path)])
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


def test_exit_code_of_non_rtp_errors() -> None:
    assert sdk.exit_code(KeyboardInterrupt()) == 130
    assert sdk.exit_code(RuntimeError()) == sdk.EXIT_FAILED == 1
    assert sdk.exit_code(sdk.InferenceError("x")) == 1 and sdk.exit_code(sdk.ParameterError("x")) == sdk.EXIT_USAGE
