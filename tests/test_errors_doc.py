"""docs/errors.md lists every error class of every room as a tree and as a table, with the parent, the
public module, the standard types and the exit code each class really has."""

from __future__ import annotations

import builtins
import importlib
import re
from pathlib import Path

from rtp import sdk

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ("rtp.sdk", "rtp.sdk.adapters", "rtp.scene", "rtp.capture", "rtp.capture.scenes", "rtp.capture.viewpoints",
         "rtp.metrics", "rtp.evaluate", "rtp.train", "rtp.train.checkpoint", "rtp.export", "rtp.plugins.moderngl",
         "rtp.plugins.pyrender", "rtp.conformance", "rtp.cli")
DOC = ROOT / "docs" / "errors.md"


def all_errors() -> dict[str, type[sdk.RtpError]]:
    """Every ``RtpError`` subclass defined in rtp, found by walking ``__subclasses__`` after importing
    every room's public modules (so a class added anywhere is picked up without a list to update)."""
    for m in ROOMS:
        importlib.import_module(m)
    out: dict[str, type[sdk.RtpError]] = {}
    todo: list[type[sdk.RtpError]] = [sdk.RtpError]
    while todo:
        cls = todo.pop()
        if cls.__module__.startswith("rtp."):
            assert cls.__name__ not in out or out[cls.__name__] is cls, f"two error classes named {cls.__name__}"
            out[cls.__name__] = cls
        todo += cls.__subclasses__()
    return out


def _parent(cls: type) -> str | None:
    parents = [b.__name__ for b in cls.__bases__ if issubclass(b, sdk.RtpError)]
    assert len(parents) <= 1, f"{cls.__name__} has more than one rtp parent: {parents}"
    return parents[0] if parents else None


def _public_module(cls: type) -> str:
    """The room module to import ``cls`` from: its module path up to the first private part."""
    parts = cls.__module__.split(".")
    public = ".".join(parts[:next((i for i, p in enumerate(parts) if p.startswith("_")), len(parts))])
    assert getattr(importlib.import_module(public), cls.__name__, None) is cls, (
        f"{cls.__name__} is not importable from {public}")
    return public


def _standard_types(cls: type) -> set[str]:
    """The most specific built-in exception types ``cls`` also is (``Exception`` for the root only)."""
    found = {b for b in cls.__mro__ if getattr(builtins, b.__name__, None) is b and b not in (object, BaseException)}
    found = {b for b in found if not any(o is not b and issubclass(o, b) for o in found)}
    return {b.__name__ for b in found if b is not Exception or cls is sdk.RtpError}


def _table() -> dict[str, tuple[str, set[str], int]]:
    rows = re.findall(r"^\| `(\w+)` \| `([\w.]+)` \|([^|]*)\| (\d+) \|", DOC.read_text(encoding="utf-8"), re.M)
    return {name: (module, set(re.findall(r"`(\w+)`", also)), int(code)) for name, module, also, code in rows}


def _tree() -> dict[str, tuple[str | None, int, str]]:
    """The fenced tree under "## The tree": name -> (parent, exit code, module)."""
    text = DOC.read_text(encoding="utf-8").split("## The tree", 1)[1]
    block = text.split("```", 2)[1]
    out: dict[str, tuple[str | None, int, str]] = {}
    stack: list[str] = []
    for line in block.strip("\n").splitlines():
        m = re.fullmatch(r"((?:[│ ]   )*)(?:[├└]── )?(\w+) +(\d+) +([\w.]+)", line)
        assert m, f"docs/errors.md: unreadable tree line {line!r}"
        depth = len(m.group(1)) // 4 + (1 if ("├" in line or "└" in line) else 0)
        del stack[depth:]
        out[m.group(2)] = (stack[-1] if stack else None, int(m.group(3)), m.group(4))
        stack.append(m.group(2))
    return out


def test_every_error_class_is_documented_with_its_exit_code() -> None:
    errors, doc = all_errors(), _table()
    assert len(errors) >= 38
    missing = sorted(set(errors) - set(doc))
    assert not missing, f"docs/errors.md does not list {missing}"
    stale = sorted(set(doc) - set(errors))
    assert not stale, f"docs/errors.md lists classes that do not exist: {stale}"
    wrong = {n: (doc[n][2], sdk.exit_code(cls("x"))) for n, cls in errors.items()
             if not doc[n][2] == cls.exit_code == sdk.exit_code(cls("x"))}
    assert not wrong, f"exit codes in docs/errors.md differ from the classes' (doc, code): {wrong}"


def test_the_table_names_each_class_module_and_standard_types() -> None:
    errors, doc = all_errors(), _table()
    modules = {n: (doc[n][0], _public_module(cls)) for n, cls in errors.items() if doc[n][0] != _public_module(cls)}
    assert not modules, f"docs/errors.md names the wrong module (doc, code): {modules}"
    also = {n: (doc[n][1], _standard_types(cls)) for n, cls in errors.items() if doc[n][1] != _standard_types(cls)}
    assert not also, f"docs/errors.md names the wrong standard types (doc, code): {also}"


def test_the_tree_is_the_class_tree() -> None:
    errors, tree = all_errors(), _tree()
    assert sorted(tree) == sorted(errors), "the tree in docs/errors.md lists other classes than the code has"
    wrong = {n: (tree[n], (_parent(cls), cls.exit_code, _public_module(cls))) for n, cls in errors.items()
             if tree[n] != (_parent(cls), cls.exit_code, _public_module(cls))}
    assert not wrong, f"docs/errors.md's tree differs from the code ((parent, exit, module): doc, code): {wrong}"


def test_every_error_class_says_what_it_means() -> None:
    for name, cls in all_errors().items():
        assert (cls.__doc__ or "").strip(), f"{name} has no docstring"
        assert cls.exit_code in (sdk.EXIT_FAILED, sdk.EXIT_USAGE), name


def test_the_path_errors_that_exit_2_are_the_ones_the_doc_lists() -> None:
    """docs/errors.md names each OSError of a wrong path that exits 2 (the runner's list): a name too long
    (ENAMETOOLONG) exited 2 and the page did not say so."""
    import errno

    from rtp.cli._run import _PATH_ERRNOS

    words = {errno.ENOENT: "missing", errno.ENOTDIR: "not a folder", errno.EISDIR: "a folder", errno.EEXIST: "exists",
             errno.EACCES: "no permission", errno.EPERM: "no permission", errno.EROFS: "read-only",
             errno.ENAMETOOLONG: "a name too long"}
    assert set(words) == _PATH_ERRNOS
    listed = re.search(r"with 2 where the path itself is wrong\s+\(([^)]*)\)", DOC.read_text(encoding="utf-8"))
    assert listed is not None
    assert set(re.split(r",\s+", " ".join(listed[1].split()))) == set(words.values()), listed[1]
