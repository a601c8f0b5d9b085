"""docs/errors.md lists every error class of every room, with the exit code the class really has."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

from rtp import sdk

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ("rtp.sdk", "rtp.sdk.adapters", "rtp.scene", "rtp.capture", "rtp.capture.scenes", "rtp.capture.viewpoints",
         "rtp.metrics", "rtp.evaluate", "rtp.train", "rtp.train.checkpoint", "rtp.export", "rtp.plugins.moderngl",
         "rtp.plugins.pyrender", "rtp.cli")


def _all_errors() -> dict[str, type[sdk.RtpError]]:
    for m in ROOMS:
        importlib.import_module(m)
    out: dict[str, type[sdk.RtpError]] = {}
    todo: list[type[sdk.RtpError]] = [sdk.RtpError]
    while todo:
        cls = todo.pop()
        if cls.__module__.startswith("rtp."):
            out[cls.__name__] = cls
        todo += cls.__subclasses__()
    return out


def _documented() -> dict[str, int]:
    text = (ROOT / "docs" / "errors.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| `([\w.]+)` \|[^|]*\| (\d+) \|", text, re.M)
    return {name: int(code) for name, _, code in rows}


def test_every_error_class_is_documented_with_its_exit_code() -> None:
    errors, doc = _all_errors(), _documented()
    assert len(errors) >= 35
    missing = sorted(set(errors) - set(doc))
    assert not missing, f"docs/errors.md does not list {missing}"
    stale = sorted(set(doc) - set(errors))
    assert not stale, f"docs/errors.md lists classes that do not exist: {stale}"
    wrong = {n: (doc[n], cls.exit_code) for n, cls in errors.items() if doc[n] != cls.exit_code}
    assert not wrong, f"exit codes in docs/errors.md differ from the classes' (doc, code): {wrong}"


def test_every_error_class_says_what_it_means() -> None:
    for name, cls in _all_errors().items():
        assert (cls.__doc__ or "").strip(), f"{name} has no docstring"
        assert cls.exit_code in (sdk.EXIT_FAILED, sdk.EXIT_USAGE), name
