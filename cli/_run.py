"""What every rtp command shares: the common options, logging through the progress bars, repeated
warnings collapsed, progress bars, and the one error policy.

Exit codes (``docs/errors.md``): 0 success (and a closed pipe); each :class:`~rtp.sdk.RtpError` its class's
``exit_code`` (2 bad usage or inputs, 1 the job failed); 130 interrupted (Ctrl-C), 143 terminated (SIGTERM);
argparse's 2 for usage errors it finds itself; 2 for an optional module that is not installed
(:data:`OPTIONAL_MODULES`); 1 for a ``MemoryError``; for an ``OSError`` that names a path, 2 where the path itself
is wrong (its errno in ``_PATH_ERRNOS``) and 1 otherwise. Any other exception outside the rtp tree is a bug: it
propagates with its traceback (exit 1).
"""

from __future__ import annotations

import argparse
import codecs
import contextlib
import errno
import logging
import os
import re
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from typing import Any, NoReturn

__all__ = ["COMMON", "Bar", "Formatter", "Parser", "add_common", "carries_metadata", "console_form", "one_line",
           "option_flags", "require_extra", "run", "run_guarded", "states_default", "version"]

log = logging.getLogger("rtp")


@contextlib.contextmanager
def out_lock(out: Any, job: str, elsewhere: str) -> Iterator[None]:
    """Hold ``--out``'s writer lock (``.rtp-writer.lock``, :func:`rtp.sdk.files.writer_lock`, removed at the end) for
    a command writing its files into the folder ``out`` (a Path; made here): a second job writing there (another
    ``rtp predict``, ``rtp evaluate`` or ``rtp play``) is refused, naming the first, before its work.
    ``elsewhere`` ends the refusal ("write into another folder"). A folder made for the lock is removed again
    where the command fails before writing into it."""
    from rtp import sdk
    from rtp.sdk.files import writer_lock

    made = [d for d in (out, *out.parents) if not d.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:  # (the folder was checked writable; a file made there since, a race)
        raise sdk.ParameterError(f"out: cannot write {str(out)!r}: {err.strerror or err}", "out") from err
    try:
        with writer_lock(out, job, lambda holder: sdk.ParameterError(
                f"out: {out} is being written by another job ({holder}): wait for it to end, or {elsewhere}", "out"),
                remove=True):
            yield
    except BaseException:
        for d in made:  # (only the empty ones: the lock's file is gone by now)
            with contextlib.suppress(OSError):
                d.rmdir()
        raise


def version() -> str:
    from rtp import sdk

    return str(sdk.__version__)


def carries_metadata(path: str) -> bool:
    """Whether ``path`` is an ONNX model that already holds rtp metadata (a file without it, or unreadable: False).
    Read with onnx where it is installed, else with onnxruntime: the runtime install has no onnx (`rtp info` of a
    model without metadata said "this needs onnx, which is not installed" instead of how to give it a sidecar)."""
    from rtp.sdk import METADATA_KEY

    try:
        import onnx
    except ImportError:
        import onnxruntime as ort

        try:
            opts = ort.SessionOptions()
            opts.log_severity_level = 3
            session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
            return METADATA_KEY in session.get_modelmeta().custom_metadata_map
        except Exception:  # not readable: the caller's load reports that
            return False
    try:
        return any(p.key == METADATA_KEY for p in onnx.load(path, load_external_data=False).metadata_props)
    except Exception:  # not readable: the caller's load reports that
        return False


def one_line(message: str) -> str:
    """``message`` with every character that is not printable (a newline or NUL from a path the user
    typed, a lone surrogate) written as its escape, so that an error stays the one line docs/errors.md
    promises and says exactly what was typed."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


#: ASCII for the characters rtp's own output holds (a table's "R² %" and "σ MAE", a status's " · "), written so on
#: a console that cannot encode them (a C/POSIX locale, PYTHONIOENCODING=ascii, a Windows console's cp1252): "R^2 %"
#: rather than a UnicodeEncodeError at the command's last line. Any other character such a console cannot show is
#: written as its escape (\xe9 for an é), or as the stream's own handler writes it (surrogateescape: a path's raw bytes).
#: (the keys, in order: ² ³ × · → ← – — ≤ ≥ ≈ ± µ μ σ ° … ‘ ’ “ ”)
ASCII_FORMS = {"\u00b2": "^2", "\u00b3": "^3", "\u00d7": "x", "\u00b7": "*", "\u2192": "->", "\u2190": "<-",
               "\u2013": "-", "\u2014": "--", "\u2264": "<=", "\u2265": ">=", "\u2248": "~", "\u00b1": "+/-",
               "\u00b5": "u", "\u03bc": "u", "\u03c3": "sigma", "\u00b0": " deg", "\u2026": "...", "\u2018": "'",
               "\u2019": "'", "\u201c": '"', "\u201d": '"'}
_ERRORS = "rtp-ascii-forms"


def _error_handler(prior: str) -> str:
    """The name of the codecs error handler that writes :data:`ASCII_FORMS`, and what it does not hold as ``prior``
    (a stream's handler until now) does, ``backslashreplace`` where that is ``strict`` or fails too."""
    name = f"{_ERRORS}+{prior}"
    try:
        codecs.lookup_error(name)
        return name
    except LookupError:
        pass
    try:
        fallback = codecs.lookup_error("backslashreplace" if prior == "strict" else prior)
    except LookupError:
        fallback = codecs.lookup_error("backslashreplace")
    escape = codecs.lookup_error("backslashreplace")

    def handler(err: UnicodeError) -> tuple[str | bytes, int]:
        if not isinstance(err, UnicodeEncodeError):
            raise err
        text, start = err.object, err.start
        if text[start] in ASCII_FORMS:
            return ASCII_FORMS[text[start]], start + 1
        stop = next((i for i in range(start, err.end) if text[i] in ASCII_FORMS), err.end)
        part = UnicodeEncodeError(err.encoding, text, start, stop, err.reason)
        try:
            return fallback(part)
        except UnicodeEncodeError:  # (surrogateescape, given a character that is not an escaped byte)
            return escape(part)

    codecs.register_error(name, handler)
    return name


@contextlib.contextmanager
def console_text() -> Iterator[None]:
    """While the block runs, stdout and stderr write what their encoding cannot as :data:`ASCII_FORMS` (else as
    escapes) instead of raising UnicodeEncodeError; UTF-8 consoles write every character as it is. The streams'
    own handlers are back afterwards (a caller's sys.stdout is left as it was). At the end, output that a closed
    pipe no longer reads (``| head -1``) is dropped, where Python's own flush at exit said "Exception ignored ...
    BrokenPipeError" and exited 120."""
    swapped = []
    for stream in (sys.stdout, sys.stderr):
        errors = getattr(stream, "errors", None)
        if not isinstance(errors, str) or errors.startswith(_ERRORS) or not hasattr(stream, "reconfigure"):
            continue
        try:
            stream.reconfigure(errors=_error_handler(errors))
        except (OSError, ValueError):  # (a closed or broken stream: left as it is)
            continue
        swapped.append((stream, errors))
    try:
        yield
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except BrokenPipeError:
                _drop(stream)
            except (AttributeError, OSError, ValueError):
                pass
        for stream, errors in swapped:
            with contextlib.suppress(OSError, ValueError):
                stream.reconfigure(errors=errors)


def console_form(text: str, stream: Any = None) -> str:
    """``text`` as ``stream`` (default: stdout) writes it, read back: under :func:`console_text` on a console that is
    not UTF-8, rtp's own characters in their :data:`ASCII_FORMS` ("R² %" as "R^2 %") and others as escapes; ``text``
    itself where the stream writes it whole (or names no encoding). For text aligned by its length (a table's
    columns), measured as it will be shown."""
    stream = sys.stdout if stream is None else stream
    encoding, errors = getattr(stream, "encoding", None), getattr(stream, "errors", None)
    if not isinstance(encoding, str) or not isinstance(errors, str):
        return text
    try:
        return text.encode(encoding, errors).decode(encoding, "replace")
    except (LookupError, UnicodeError):  # (a strict stream outside console_text: it writes nothing of it anyway)
        return text


def _drop(stream: Any) -> None:
    """Point ``stream``'s file descriptor at the null device: its reader has gone (``| head -1``), and what is still
    written to it, or left in its buffer for Python's flush at exit, must not fail again."""
    with contextlib.suppress(AttributeError, OSError, ValueError):
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, stream.fileno())
        finally:
            os.close(null)


def _say(line: str) -> None:
    """``line`` on stderr; nothing where stderr's reader has gone (``2>&1 | head -1``): the exit code stays the
    command's, where a BrokenPipeError from the error's own line replaced it."""
    try:
        print(line, file=sys.stderr)
    except BrokenPipeError:
        _drop(sys.stderr)


class Parser(argparse.ArgumentParser):
    """argparse's parser (its subcommands' too), with two fixes: ``--flag=--``, and a literal ``--``
    given as a positional after the ``--`` that ends the options (``rtp metric flip -- -- b.png``), give
    the value ``--``, refused or taken by its type like any other (Python 3.11's argparse strips the
    ``--`` and passes an empty list, which reached the commands, ``float([])``, ``[].split``, Pillow's
    ``open([])``, as a TypeError or AttributeError); and a usage error is one line even when it quotes
    an argument holding a newline."""

    def error(self, message: str) -> NoReturn:
        """argparse's usage error, on one line whatever the arguments it quotes hold: a control
        character (a newline in ``--out=$'\\n'``) or a lone surrogate is written as its escape."""
        super().error(one_line(message))

    def _get_values(self, action: argparse.Action, arg_strings: list[str]) -> Any:
        # (a positional is handed ["--"] only for a literal "--": the "--" that ends the options goes
        # with the strings before it, and a single value must include one that is not an option)
        if action.nargs is None and arg_strings == ["--"]:
            value = self._get_value(action, "--")
            self._check_value(action, value)
            return value
        return super()._get_values(action, arg_strings)


class Formatter(argparse.RawDescriptionHelpFormatter):
    """Help that shows every default (unless the help text states it already as ``default: ...``, or
    there is none to show: a required option, a flag, an option whose absence means something the help
    says) and keeps the examples' line breaks."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        # (by identity: `in` compares with ==, and a default of 0, `--seed`'s, equals False and was not shown)
        if (states_default(text) or action.required or any(action.default is d for d in (None, False, argparse.SUPPRESS))
                or not action.option_strings):
            return text
        return text + " (default: %(default)s)"


def states_default(help_text: str) -> bool:
    """Whether a help text says its default itself (``(default: ...)`` or ``...; default: ...``): a
    help that merely mentions the word, such as "$RTP_SCENE_CACHE overrides the default", does not."""
    return "default:" in help_text


def add_common(parser: argparse.ArgumentParser, *, top: bool) -> None:
    """The options every command takes, before or after the subcommand (``rtp -v capture`` and
    ``rtp capture -v`` alike): a subcommand's copies default to SUPPRESS so they never undo the top's."""
    default: Any = False if top else argparse.SUPPRESS
    g = parser.add_argument_group("output")
    # (a subcommand's own dest: argparse copies a subcommand's namespace over the top's, so `rtp -v
    # capture -v` counted one; run() adds the two)
    g.add_argument("-v", "--verbose", action="count", default=default, dest="verbose" if top else "verbose_after",
                   help="log progress; show tracebacks (-vv: and rtp's own details, such as each frame's render "
                   "time and each metric's time per sample)")
    g.add_argument("-q", "--quiet", action="store_true", default=default, help="only errors; no progress bars")
    g.add_argument("--no-progress", action="store_true", default=default, help="no progress bars")
    if top:
        parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")


COMMON = ("verbose", "quiet", "no_progress")


class _Collapse(logging.Filter):
    """Lets the first warning or error of each (logger, message template, level) through and counts
    the rest; :meth:`summary` reports the counts once the command ends. Progress (INFO, ``-v``) is
    never collapsed: it collapsed too, so `rtp -v train` logged its first validation step only and `rtp
    -v capture` the first job's planning time."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: dict[tuple[str, str, int], list[Any]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        key = (record.name, str(record.msg), record.levelno)
        if key in self.seen:
            self.seen[key][0] += 1
            return False
        self.seen[key] = [0, record.getMessage()]
        return True

    def summary(self) -> list[str]:
        """The counts of the repeats held back since the last summary (each is said once)."""
        lines = [f"{n} more like: {first}" for (n, first) in self.seen.values() if n]
        for counted in self.seen.values():
            counted[0] = 0
        return lines

    def say(self) -> None:
        for line in self.summary():
            _say(f"WARNING (repeated): {line}")


def _rtp_details(record: logging.LogRecord) -> bool:
    """With ``-vv``: DEBUG records of rtp's own loggers only (numpy's, PIL's or Ray's debug chatter
    would bury them)."""
    return record.levelno >= logging.INFO or record.name == "rtp" or record.name.startswith("rtp.")


class _Handler(logging.StreamHandler):
    """stderr, written as ``tqdm.write`` writes (see :meth:`_write`) where tqdm is installed, so that a log line never tears a
    progress bar. (tqdm's own ``logging_redirect_tqdm`` swapped this handler for one of its own, which
    at pyproject's floor, tqdm 4.60, wrote to stdout, into the JSON of `rtp info --json`, and before
    tqdm#1775 kept none of its filters: repeated warnings were not collapsed and `-vv` logged every
    library's debug chatter.)"""

    def __init__(self) -> None:
        super().__init__(sys.stderr)
        self._tqdm: Any = None
        with contextlib.suppress(ImportError):
            from tqdm import tqdm

            self._tqdm = tqdm

    def emit(self, record: logging.LogRecord) -> None:
        if self._tqdm is None:
            super().emit(record)
            return
        try:
            self._write(self.format(record))
        except RecursionError:
            raise
        except Exception:  # noqa: BLE001 - logging's own policy for a handler that fails
            self.handleError(record)

    def _write(self, line: str) -> None:
        """``line`` with the bars on screen cleared before it and drawn again after it, as ``tqdm.write`` does,
        but only the bars that are on screen: ``tqdm.write`` also drew a bar still within its delay (its
        "refresh"), which tqdm then took for never shown, so its close did not end its line: a warning in a job's
        first half second drew the bar at once, put ``\r\r`` before the line in a log, and left the bar's text
        in front of the next line (`rtp train`'s "3/3 [00:00, loss=0.0814]rtp train: error: dead output(s)")."""
        tqdm = self._tqdm
        with tqdm.get_lock():
            shown = [bar for bar in list(getattr(tqdm, "_instances", ())) if _on_screen(bar, self.stream)]
            for bar in shown:
                bar.clear(nolock=True)
            self.stream.write(line + self.terminator)
            for bar in shown:
                bar.refresh(nolock=True)
            self.flush()


def _on_screen(bar: Any, stream: Any) -> bool:
    """Whether tqdm ``bar`` is drawn where ``stream`` shows (the same file, or both on the terminal's stdout and
    stderr) and is past its delay: drawn, by tqdm's own account (its ``close`` ends or erases only such a bar)."""
    if getattr(bar, "disable", True) or not hasattr(bar, "start_t"):
        return False
    if not (bar.fp == stream or all(f in (sys.stdout, sys.stderr) for f in (bar.fp, stream))):  # (fp: tqdm's wrapper)
        return False
    return bool(bar.last_print_t >= bar.start_t + getattr(bar, "delay", 0.0))


def _console(handler: logging.Handler) -> bool:
    return isinstance(handler, logging.StreamHandler) and handler.stream in (sys.stdout, sys.stderr)


@contextlib.contextmanager
def _logging(args: argparse.Namespace) -> Iterator[_Collapse]:
    verbose = int(args.verbose or 0)  # (-v once: progress; twice: rtp's debug details too)
    level = logging.DEBUG if verbose >= 2 else logging.INFO if verbose else logging.ERROR if args.quiet else logging.WARNING
    handler = _Handler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    # (the handler's level too: a library logger with a level of its own, below the root's, passes its
    # records to the root's handlers whatever the root's level, and -q showed its warnings)
    handler.setLevel(level)
    collapse = _Collapse()
    handler.addFilter(collapse)
    if level == logging.DEBUG:
        handler.addFilter(_rtp_details)
    root = logging.getLogger()
    old_level, old_handlers = root.level, root.handlers
    # the console handlers already there (a script's basicConfig) are set aside while the command runs,
    # as tqdm's redirection did, so that no line is written twice
    root.handlers = [h for h in old_handlers if not _console(h)] + [handler]
    root.setLevel(level)
    try:
        yield collapse
    finally:
        root.handlers = old_handlers
        root.setLevel(old_level)
        collapse.say()


class Bar:
    """A tqdm progress bar (when tqdm is installed and bars are wanted), else nothing."""

    #: Seconds before a bar first shows.
    DELAY = 0.5
    #: Seconds between two draws of :meth:`status`.
    STATUS_EVERY = 0.1

    def __init__(self, args: argparse.Namespace, total: int, desc: str, unit: str) -> None:
        self.total = total
        #: The count last given to :meth:`update_to` (shown or not): what a job's interruption says is done.
        self.done = 0
        self._bar: Any = None
        self._status = ""
        self._sticky = False
        self._drawn = 0.0
        self._lock = threading.Lock()  # (the status's state, shared with its timer)
        self._timer: threading.Timer | None = None
        self._closed = False
        if args.quiet or args.no_progress:
            return
        with contextlib.suppress(ImportError):
            from tqdm import tqdm

            # delay: a job that fails at once (a bad argument found by the job itself) never shows a bar,
            # so its error stands alone on the terminal and in a log.
            self._bar = tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True, delay=self.DELAY)

    def update_to(self, n: int, total: int | None = None, **postfix: str) -> None:
        self.done = n
        if self._bar is None:
            return
        if total is not None and total != self._bar.total:
            self._bar.total = total
        if self._status and not self._sticky and n != self._bar.n:  # the count moves: what held it is over
            with self._lock:
                self._status = ""
                self._bar.set_postfix_str("", refresh=False)
        self._bar.update(n - self._bar.n)
        if postfix:
            self._bar.set_postfix(postfix, refresh=False)

    def status(self, text: str = "", *, sticky: bool = False) -> None:
        """Show ``text`` after the count (empty: nothing) while the count does not move, as a long
        first step runs (the next step clears it; ``sticky``: only the next status does, as for the
        steps of `rtp play`'s paths in parallel, one writing its GIF while another's frames count);
        drawn at most every ``STATUS_EVERY`` s and not before the bar's delay: a text that comes sooner
        is drawn then (by a timer) if it is still the one to show, so that the last step of a quick
        succession is on screen while it runs."""
        bar = self._bar
        if bar is None or (text == self._status and sticky == self._sticky):
            return
        with self._lock:
            self._status, self._sticky = text, sticky
            bar.set_postfix_str(text, refresh=False)
        self._draw_status()

    def _draw_status(self) -> None:
        with self._lock:
            self._timer = None if self._timer is threading.current_thread() else self._timer
            if self._closed or not self._status:
                return
            bar = self._bar
            now = time.time()  # (tqdm's clock)
            wait = max(bar.start_t + self.DELAY - now, self._drawn + self.STATUS_EVERY - now)
            if wait <= 0:
                self._drawn = bar.last_print_t = now  # (tqdm's close ends or erases only a bar it knows it drew)
                bar.refresh()
            elif self._timer is None:
                self._timer = threading.Timer(wait, self._draw_status)
                self._timer.daemon = True
                self._timer.start()

    def close(self) -> None:
        with self._lock:
            self._closed = True
            if self._timer is not None:
                self._timer.cancel()
        if self._bar is not None:
            self._bar.close()

    def __enter__(self) -> Bar:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        if exc_type is None and self._bar is not None and self._status:
            # a job that ended well ends on its count, not on the last step it was in
            self._bar.set_postfix_str("", refresh=False)
        if exc_type is not None and self._bar is not None and self._bar.n == 0:
            # The job failed before any progress: a terminal erases the empty bar, so that the error
            # message stands alone. A file or a pipe cannot erase: there the bar ends its line instead
            # of leaving its text and carriage returns in front of the error.
            tty = getattr(self._bar.fp, "isatty", lambda: False)()
            self._bar.leave = not tty
        self.close()


def _kept(on_interrupt: Callable[[], Callable[[], str] | None] | None) -> str:
    """``; `` and the interrupted command's account of what it kept and how to go on, or nothing (no
    account, or one that failed: the interruption is said all the same)."""
    try:
        account = on_interrupt() if on_interrupt is not None else None
        text = account() if account is not None else ""
    except (Exception, KeyboardInterrupt):  # noqa: BLE001 - a second Ctrl-C or a broken file must not hide the first
        return ""
    return f"; {one_line(text)}" if text else ""


#: The optional modules rtp's commands import as they run, and the extra of pyproject.toml that installs each: a
#: command run without one (`rtp predict --out` on the runtime install, without Pillow; `rtp-export` without onnx) says
#: so in one line and exits 2, a missing install (docs/errors.md), where it was a traceback and 1. Each is the extra
#: with the fewest requirements among those that bring the module, one without torch where there is one
#: (tests/test_dependencies.py checks them against pyproject.toml): flip-evaluator's is rtp[capture], not
#: rtp[metrics], which has torch too. torch's is training's (the commands that import it bare are `rtp train`'s;
#: `rtp-export`'s is rtp[export], and a metric's own check names rtp[metrics]).
OPTIONAL_MODULES = {"torch": "rtp[train]", "onnx": "rtp[export]", "moderngl": "rtp[moderngl]", "glcontext": "rtp[moderngl]",
                    "PIL": "rtp[capture]", "imageio": "rtp[capture]", "matplotlib": "rtp[capture]",
                    "trimesh": "rtp[capture]", "tqdm": "rtp[capture]", "png": "rtp[capture]",
                    "flip_evaluator": "rtp[capture]", "pyrender": "rtp[pyrender]", "OpenGL": "rtp[pyrender]",
                    "ray": "rtp[ray]"}

#: What a missing torch's message adds: the pin of pyproject.toml may come from public PyPI as the CUDA build
#: (README, "Set-up"); ``rtp.metrics``' messages say the same (tests/test_dependencies.py).
_TORCH_CPU_NOTE = ("torch from public PyPI may be its CUDA build, gigabytes: for the CPU build add --extra-index-url "
                   "https://download.pytorch.org/whl/cpu (README, Set-up)")


#: The name pip installs an optional module by, where it is not the module's.
_DISTRIBUTIONS = {"PIL": "Pillow", "flip_evaluator": "flip-evaluator", "png": "pypng", "OpenGL": "PyOpenGL"}


def require_extra(extra: str, modules: Iterable[str]) -> None:
    """Import each of ``modules`` (of :data:`OPTIONAL_MODULES`, such as ``"PIL.Image"``), what a command needs of
    ``extra`` (``"rtp[capture]"``), before the command's work: those not installed are named together in one
    ImportError naming ``extra``, which the error policy says in one line, exit 2. `rtp demo` on the runtime install
    named flip-evaluator alone (``pip install flip-evaluator==1.7``), then with it moderngl (``rtp[moderngl]``), then,
    after rendering and predicting, matplotlib: three installs, one at a time, where ``rtp[capture]`` brings them all."""
    import importlib

    missing: list[str] = []
    for name in modules:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as err:
            top = (err.name or "").partition(".")[0]
            if top not in OPTIONAL_MODULES:
                raise  # (installed, and broken: a module of its own is missing; its traceback says which)
            missing.append(top)
    if missing:
        names = [_DISTRIBUTIONS.get(m, m) for m in dict.fromkeys(missing)]
        listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
        raise ImportError(f"this needs {listed}, which {'is' if len(names) == 1 else 'are'} not installed: "
                          f"pip install '{extra}'") from ModuleNotFoundError(f"No module named {missing[0]!r}",
                                                                               name=missing[0])


def _missing_install(prog: str, err: ImportError) -> str | None:
    """The one-line message for ``err`` where it (or the error it was raised from) is an optional module of
    :data:`OPTIONAL_MODULES` that is not installed; None for any other import error (rtp's own: a bug, or a module
    installed but broken, which keeps its traceback)."""
    cause: BaseException | None = err
    while cause is not None and not (isinstance(cause, ModuleNotFoundError) and cause.name in OPTIONAL_MODULES):
        cause = cause.__cause__
    if cause is None:
        return None
    if cause is not err:  # an rtp module's own words around it ("the rtp reference renderer needs moderngl; ...")
        return str(err)
    name = str(cause.name)
    extra = "rtp[export]" if prog == "rtp-export" and name in ("torch", "onnx") else OPTIONAL_MODULES[name]
    return f"this needs {name}, which is not installed: pip install '{extra}'" + (
        f"; {_TORCH_CPU_NOTE}" if name == "torch" else "")


#: The errors of a path that is wrong in itself (a usage error, exit 2), not of a job that failed.
_PATH_ERRNOS = frozenset({errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EEXIST, errno.EACCES, errno.EPERM,
                          errno.EROFS, errno.ENAMETOOLONG})


def option_flags(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Each option's flag by the name the code gives its value (``fail_threshold``: ``--fail-threshold``); an
    option given once per value (``--path``) also by its plural, the library's argument (``paths``)."""
    flags: dict[str, str] = {}
    for action in parser._actions:
        long = [o for o in action.option_strings if o.startswith("--")]
        if isinstance(action, argparse.BooleanOptionalAction):
            long = long[:1]  # (--augment, not its --no-augment)
        if long and action.dest not in ("help", "version"):
            flags[action.dest] = long[-1]
            if isinstance(action, argparse._AppendAction) and not action.dest.endswith("s"):
                flags.setdefault(action.dest + "s", long[-1])
    return flags


# a message that begins with the argument it is about: "flip_every: expected ...", "ppd must be ...", "weber_l (...)"
_ABOUT = re.compile(r"(\w+)(?=: | must | \()")


def _in_flags(err: BaseException, flags: dict[str, str]) -> None:
    """A parameter error that names a library argument, said with the command's flag for it (docs/errors.md:
    messages in the caller's words)."""
    from rtp.sdk import ParameterError

    text = str(err)
    about = _ABOUT.match(text)
    if isinstance(err, ParameterError) and about and about[1] in flags and err.args == (text,):
        err.args = (flags[about[1]] + text[about.end():],)


def run(prog: str, args: argparse.Namespace, body: Callable[[argparse.Namespace], int],
        flags: dict[str, str] | None = None) -> int:
    """Run a command body under the one error policy (see the module docstring). ``flags`` (:func:`option_flags`
    of the command's parser): a parameter error that names an argument by its Python name names its flag."""
    args.verbose = int(getattr(args, "verbose", 0) or 0) + int(getattr(args, "verbose_after", 0) or 0)

    with _logging(args) as repeats:
        def body_in_flags() -> int:
            try:
                return body(args)
            except Exception as err:
                _in_flags(err, flags or {})
                raise
            finally:
                # the repeats' counts before the error's line (or the interruption's), not after it: the error
                # is the last line, as docs/errors.md has it, and `tail -1` of a log finds it
                repeats.say()

        return run_guarded(prog, body_in_flags, verbose=args.verbose,
                           on_interrupt=lambda: getattr(args, "on_interrupt", None))


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, ``docker stop``, a job scheduler) while a command runs: it unwinds as Ctrl-C
    does (workers stopped, what is written kept, the account of it printed), and exits 143."""


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` in the main thread while the block runs (elsewhere: nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminated(signum: int, frame: Any) -> None:
        raise Terminated()

    before = signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def _notes(err: BaseException) -> str:
    """The notes a worker pool adds to a failure it passes on ("(rtp: raised while working on scene 'x')"),
    on the same line: the one-line messages of a MemoryError or an OSError would otherwise lose which scene or
    sample failed."""
    notes = getattr(err, "__notes__", None) or []
    return "".join(" " + one_line(str(note)) for note in notes)


def interruptible_start(prog: str, start: Callable[[], int]) -> int:
    """``start()``: an entry point that loads rtp's modules, reads its arguments and then runs its command under
    :func:`run_guarded`. Ctrl-C before that (the imports and argparse take about half a second) says ``PROG:
    interrupted`` and returns 130, as it does once the command runs, instead of a traceback of the import it
    landed in; so does one that escapes the command's own policy (a second Ctrl-C while it says the first)."""
    with console_text():  # (argparse's help too: `rtp train -h` under LC_ALL=C)
        try:
            return start()
        except KeyboardInterrupt:  # (nothing imported here: the interrupt may have cut rtp.sdk's own import short)
            with contextlib.suppress(KeyboardInterrupt, OSError):
                print(f"{prog}: interrupted", file=sys.stderr)
            return 128 + signal.SIGINT  # (the sdk's EXIT_INTERRUPTED)


def run_guarded(prog: str, body: Callable[[], int | None], *, verbose: bool = False,
                on_interrupt: Callable[[], Callable[[], str] | None] | None = None) -> int:
    """``body()`` under the one error policy, without rtp's logging set-up: an rtp error prints one line,
    ``PROG: error: MESSAGE``, and returns its class's exit code (``verbose``: the traceback above it); an
    ``OSError`` naming a path likewise (2 for a wrong path, 1 otherwise); a ``MemoryError`` one line
    (1); an optional module that is not installed (:data:`OPTIONAL_MODULES`) one line naming its extra (2);
    Ctrl-C 130 (SIGTERM 143, ``PROG: terminated``), saying ``PROG: interrupted`` and what of the job is kept where
    ``on_interrupt`` gives the command's own account (``args.on_interrupt``, set by a resumable command once it
    starts); a closed pipe 0.
    Anything else propagates with its traceback. The benchmark scripts under ``bench/`` run through it."""
    with console_text():
        return _run_guarded(prog, body, verbose=verbose, on_interrupt=on_interrupt)


def _run_guarded(prog: str, body: Callable[[], int | None], *, verbose: bool,
                 on_interrupt: Callable[[], Callable[[], str] | None] | None) -> int:
    from rtp.sdk import EXIT_FAILED, EXIT_USAGE, RtpError, exit_code

    try:
        with _terminate_as_interrupt():
            return int(body() or 0)
    except RtpError as err:
        if verbose:
            traceback.print_exc()
        _say(f"{prog}: error: {one_line(str(err))}")
        return exit_code(err)
    except KeyboardInterrupt as err:
        _say(f"{prog}: {'terminated' if isinstance(err, Terminated) else 'interrupted'}{_kept(on_interrupt)}")
        return 128 + signal.SIGTERM if isinstance(err, Terminated) else exit_code(err)
    except MemoryError as err:  # numpy's "Unable to allocate 30.5 GiB for an array ...": the machine's limit, not a bug
        if verbose:
            traceback.print_exc()
        _say(f"{prog}: error: out of memory: {one_line(str(err)) or 'an allocation failed'}{_notes(err)}")
        return EXIT_FAILED
    except ImportError as err:
        missing = _missing_install(prog, err)
        if missing is None:  # (rtp's own import failing: a bug, with its traceback)
            raise
        if verbose:
            traceback.print_exc()
        _say(f"{prog}: error: {one_line(missing)}")
        return EXIT_USAGE
    except BrokenPipeError:  # output piped into a program that stopped reading (head, less)
        _drop(sys.stdout)
        return 0
    except OSError as err:
        if err.filename is None:  # not about a path the user gave: a bug, with its traceback
            raise
        # A path the system refused (a folder where a file was asked, a read-only place, a full
        # disk): the user's to fix, said in one line; 2 where the path itself is wrong.
        if verbose:
            traceback.print_exc()
        where = f"{err.filename!r}" + (f" -> {err.filename2!r}" if err.filename2 else "")
        _say(f"{prog}: error: {err.strerror or type(err).__name__}: {where}{_notes(err)}")
        return EXIT_USAGE if err.errno in _PATH_ERRNOS else EXIT_FAILED
