"""Atomic file output, shared by every writer in rtp (checkpoints, exports, datasets, targets).

Public so that every room (and a user's own tools) writes files the same way::

    from rtp.sdk.files import atomic_output
    with atomic_output("model.onnx") as tmp:
        tmp.write_bytes(data)          # renamed over model.onnx only if this block succeeds

and checks an output path before the work that fills it (:func:`check_output`), so that a job
that would fail at its first write fails before it starts. :func:`writer_lock` keeps a second job
from writing a folder a first one is writing.
"""

from __future__ import annotations

import contextlib
import difflib
import functools
import logging
import os
import re
import stat
import tempfile
import zipfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ._errors import ParameterError

__all__ = ["LOCK_NAME", "array_headers", "atomic_output", "check_output", "frame_files", "read_frame", "read_sidecar",
           "writer_lock", "yaml_problem"]

log = logging.getLogger("rtp.sdk.files")

#: The lock file :func:`writer_lock` keeps in a folder it guards.
LOCK_NAME = ".rtp-writer.lock"


def _umask() -> int:
    """The process's umask, read where the system shows it (Linux's ``/proc/self/status``): setting it to 0 and back
    to read it, the fallback, leaves a moment in which a file another thread creates is writable by everyone."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _default_mode(target: Path | None = None) -> int:
    # mkstemp creates files readable by their owner only; give the result the permissions an
    # ordinary open() would: an existing file's own (a write through open() keeps them: a model made
    # private with chmod 600 came back 0o644, readable by everyone, once written again), else 0o666
    # minus the umask, so exported models stay shareable.
    if target is not None:
        try:
            st = os.stat(target)
        except (OSError, ValueError):
            pass
        else:
            if stat.S_ISREG(st.st_mode):
                return stat.S_IMODE(st.st_mode) & 0o777
    return 0o666 & ~_umask()


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is fsynced and renamed over ``path``, with the
    permissions ``open(path, "w")`` would leave: those of the file it replaces, else ``0o666`` less the umask.

    If the body raises, the temporary file is removed and ``path`` keeps its previous content, so a
    reader never sees a half-written file. A system error that names no file (a full disk, a quota,
    an I/O error: what a write into an open file raises) is raised again naming ``path``, the file
    that could not be written, as an ``OSError`` of the same ``errno``. The temporary file of an earlier
    write of ``path`` whose process was killed (``kill -9``: no cleanup ran) is removed, once no process
    holds it and it is a minute old (where the system has ``flock``).
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as err:  # (a read-only folder, a full disk: the error named the temporary file, not the one asked for)
        if err.errno is None:
            raise
        raise OSError(err.errno, err.strerror or os.strerror(err.errno), str(target)) from err
    if not _hold(fd):  # (held while this write lives: a later write of the target can tell it is not orphaned)
        os.close(fd)  # (not held: closed at once, as before; Windows cannot replace a file left open)
        fd = -1
    tmp_path = Path(tmp)
    try:
        _remove_orphans(target, tmp_path)
        yield tmp_path
        with open(tmp_path, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp_path, _default_mode(target))
        os.replace(tmp_path, target)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        if isinstance(err, OSError) and err.filename is None and err.errno is not None:
            # ("[Errno 28] No space left on device" alone: which file, and so which disk, is the user's to know)
            raise OSError(err.errno, err.strerror or os.strerror(err.errno), str(target)) from err
        raise
    finally:
        if fd >= 0:
            os.close(fd)


#: How old (by modification time) an unlocked temporary file of :func:`atomic_output` must be before a later write
#: of the same file removes it: a writer takes its lock just after creating the file, so a young one may be alive.
ORPHAN_AGE_S = 60.0


def _hold(fd: int) -> bool:
    """Take an exclusive ``flock`` on a temporary file of :func:`atomic_output`, for as long as ``fd`` is open (the
    system drops it when the process ends, ``kill -9`` included); False where there is no ``flock``."""
    try:
        import fcntl

        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (ImportError, OSError):  # (not POSIX, or a file system that refuses locks: no cleanup of its orphans)
        return False
    return True


def _remove_orphans(target: Path, mine: Path) -> None:
    """Remove the temporary files of earlier writes of ``target`` whose process died without cleaning up (a
    ``kill -9``, a power cut: ``.model.onnx.k2j4x9ab.tmp`` stayed beside the file for good): those no live process
    holds the lock of (:func:`_hold`) and older than :data:`ORPHAN_AGE_S`. Only the names this function gives."""
    try:
        import fcntl
    except ImportError:
        return
    import time

    pattern = re.compile(rf"\.{re.escape(target.name)}\.[A-Za-z0-9_]{{8}}\.tmp")
    now = time.time()
    try:
        candidates = [p for p in target.parent.iterdir() if p != mine and pattern.fullmatch(p.name)]
    except OSError:
        return
    for p in candidates:
        try:
            fd = os.open(p, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            continue
        try:
            if not os.path.isfile(p) or now - os.fstat(fd).st_mtime < ORPHAN_AGE_S:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # (held: a live write)
                continue
            with contextlib.suppress(OSError):
                p.unlink()
                log.info("%s: removed %s, the temporary file of a write that was killed", target, p.name)
        finally:
            os.close(fd)


@contextlib.contextmanager
def writer_lock(folder: str | os.PathLike[str], job: str, busy: Callable[[str], Exception], *,
                name: str = LOCK_NAME, remove: bool = False) -> Iterator[None]:
    """Hold the writer lock of ``folder`` (an exclusive ``flock`` on its file ``name``) for the block;
    while another process holds it, raise ``busy(holder)`` at once, ``holder`` what that process
    wrote there (``"rtp capture, pid 1234"``; ``job`` is what this one writes).

    The system releases the lock when its process exits, however it ends (``kill -9`` included), so
    a crash leaves no stale lock to clear by hand. ``remove=True`` deletes the lock file at the end of
    the block (a lock beside a file rather than in a folder of its own); a process that locked the
    file just as it was deleted finds it gone and locks the new one. The lock is advisory: it keeps
    rtp's jobs apart, not other programs. Where the system has no ``flock`` (Windows) the block runs
    unguarded, and so it does, with a warning, on a file system that refuses locks (some NFS mounts).
    """
    try:
        import fcntl
    except ImportError:  # (not POSIX)
        yield
        return
    path = Path(folder) / name
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "another process"
            os.close(fd)
            raise busy(holder) from None
        except OSError as err:  # a file system without locks (some NFS and FUSE mounts: ENOLCK, EOPNOTSUPP)
            os.close(fd)
            log.warning("%s: this file system takes no locks (%s); %s runs without its writer lock", path,
                        err.strerror or err, job)
            fd = -1
            break
        try:
            if os.fstat(fd).st_ino == os.stat(path).st_ino:
                break  # (else a holder removed the file between our open and lock: lock the one there now)
        except FileNotFoundError:
            pass
        os.close(fd)
    if fd < 0:
        yield
        return
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{job}, pid {os.getpid()}".encode(), 0)
        yield
    finally:
        if remove:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()  # (while still held, so nobody holds the name in between)
        os.close(fd)  # (releases the lock)


def check_output(path: str | os.PathLike[str], *, folder: bool = False, what: str = "output") -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file (``folder=False``) or a folder (``folder=True``)
    can be written there, else a :class:`~rtp.sdk.ParameterError` that says why, naming ``what`` (the
    option). Nothing is created: the nearest existing folder above ``path`` is probed with a
    temporary file, removed at once (a read-only or pseudo file system fails there, as it would at
    the first write of a long job)."""
    if not isinstance(path, (str, os.PathLike)) or "\0" in str(os.fspath(path)):  # (NUL: the system's ValueError)
        raise ParameterError(f"{what}: expected a path, got {path!r}", what)
    target = Path(path)
    try:
        exists = target.exists()
    except OSError as err:  # a name too long for the file system
        shown = str(target) if len(str(target)) <= 120 else str(target)[:117] + "..."
        raise ParameterError(f"{what}: cannot write {shown!r}: {err.strerror or err}", what) from err
    if exists and target.is_dir() != folder:
        kind = "a folder" if target.is_dir() else "a file"
        raise ParameterError(f"{what}: {str(target)!r} is {kind}; expected {'a folder' if folder else 'a file'} path",
                             what)
    parent = target if folder else target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise ParameterError(f"{what}: cannot write {str(target)!r}: {str(parent)!r} is a file, not a folder", what)
    try:
        fd, probe = tempfile.mkstemp(prefix=".rtp-write-check.", dir=parent)
    except OSError as err:
        raise ParameterError(f"{what}: cannot write {str(target)!r}: {err.strerror or err} in {str(parent)!r}",
                             what) from err
    os.close(fd)
    os.unlink(probe)
    return target


def yaml_problem(err: BaseException) -> str:
    """A YAML parser's error (problem, context, the line quoted with a caret under it) as one line,
    for the one-line messages of rtp's errors."""
    return " ".join(line.strip() for line in str(err).splitlines() if line.strip() and set(line.strip()) != {"^"})


def _natural(name: str) -> list[Any]:
    """The sort key of a natural order: ``frame_9`` before ``frame_10``."""
    # (the odd parts are the digit runs: str.isdigit() holds for '²' too, whose int() raised a ValueError)
    return [int(t) if i % 2 else t for i, t in enumerate(re.split(r"(\d+)", name))]


def frame_files(paths: Iterable[str | os.PathLike[str]] | str | os.PathLike[str], *,
                example: str = "rtp predict FOLDER --write-example --frames 8") -> list[str]:
    """The frame files ``paths`` name: each an ``.npz``, or a folder whose ``*.npz`` are taken in the natural
    order of their names (``frame_9`` before ``frame_10``; names of the same numbers, ``frame_01`` and ``frame_1``,
    in the order of their characters). One path (a ``str`` or ``os.PathLike``) is taken as a list of one. A folder
    without one is a :class:`ParameterError` whose hint is ``example`` (a command that writes frames)."""
    if isinstance(paths, (str, os.PathLike)):  # (not its letters: "frames" was read as the paths 'f', 'r', ...)
        paths = [paths]
    files: list[str] = []
    for path in paths:
        if Path(path).is_dir():
            # (the name breaks a tie of the natural order: else the file system's listing order decided it)
            found = sorted(Path(path).glob("*.npz"), key=lambda f: (_natural(f.name), f.name))
            if not found:
                raise ParameterError(f"{os.fspath(path)!r}: a folder with no .npz frame in it (`{example}` writes "
                                     f"a sequence of the reference renderer)", "frame")
            files += [str(f) for f in found]
        else:
            files.append(os.fspath(path))
    return files


def array_headers(path: str | os.PathLike[str]) -> dict[str, tuple[tuple[int, ...], np.dtype[Any]]]:
    """The shape and dtype of each array of an ``.npz`` file (a frame of :func:`read_frame`), read from the arrays'
    headers: no array is loaded (a pickled object array is not unpickled, a huge one takes no memory), so a tool can
    check a file's arrays, and the memory they take, before it reads them. A file that is no ``.npz`` numpy can read
    is a :class:`ParameterError` naming it and what zipfile or numpy said."""
    out: dict[str, tuple[tuple[int, ...], np.dtype[Any]]] = {}
    try:
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with z.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                              else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = header(fh)
                out[info.filename[:-4]] = (tuple(int(n) for n in shape), dtype)
    except Exception as err:  # (zipfile and numpy on damaged bytes: BadZipFile, zlib.error, EOFError, ValueError, ...)
        raise ParameterError(f"{os.fspath(path)!r}: not an .npz of arrays numpy can read ({type(err).__name__}: "
                             f"{err})", "path") from None
    return out


def read_frame(path: str | os.PathLike[str], *, extra: Iterable[str] = (),
               example: str = "rtp predict FRAME.npz --write-example") -> dict[str, Any]:
    """The arrays of a frame file, each named as a G-buffer of :data:`rtp.sdk.GBUFFERS` or in ``extra``;
    others are named in a logged warning, with the name they may have meant, and not returned. A path that
    is no file or no ``.npz`` numpy reads is a :class:`ParameterError` (its hint: ``example``, a command that
    writes one), and so is a damaged ``.npz`` (a deflate stream, a CRC or an array header numpy cannot
    read), naming the file and what numpy said. Only the arrays returned are read: another array (an engine's
    own metadata, saved as a pickled object array) is named and left unread; one returned that is a pickled object
    array is a :class:`ParameterError` naming it (numpy's ``allow_pickle=False``: unpickling runs code the file
    holds), and so is one numpy cannot allocate (``MemoryError``: a frame too large for the machine, or a header that
    says a wrong shape), naming the array."""
    from ._planes import GBUFFERS

    p = Path(path)
    name = os.fspath(path)
    if not p.is_file():
        raise ParameterError(f"{name!r}: no such file (expected an .npz of G-buffers: `{example}` writes one from "
                             f"the reference renderer)", "frame")
    if not zipfile.is_zipfile(p):
        raise ParameterError(f"{name!r}: not an .npz (numpy.savez's zip of arrays)", "frame")
    known = (*GBUFFERS, *extra)
    arrays: dict[str, Any] = {}
    try:
        with np.load(p, allow_pickle=False) as npz:
            files = list(npz.files)
            for key in files:
                if key not in known:  # (not read: an engine's own extra array, pickled or huge, is no reason to refuse)
                    continue
                try:
                    arrays[key] = npz[key]
                except MemoryError as err:  # (not damage: a frame too large, or a header that says a wrong shape)
                    raise ParameterError(
                        f"{name!r}: {key} does not fit in memory, numpy cannot allocate the array its header "
                        f"describes ({err}): a frame too large for this machine, or a header that says a wrong shape",
                        key) from None
                except ValueError as err:
                    if "allow_pickle" not in str(err):
                        raise
                    raise ParameterError(
                        f"{name!r}: {key} is a pickled object array (numpy's dtype object, as np.savez saves a dict, "
                        f"a list of arrays of unequal shapes or other Python objects), which rtp does not load "
                        f"(allow_pickle=False: unpickling runs code the file holds): save it as an array of numbers, "
                        f"e.g. np.asarray({key}, np.float32)",
                        key) from None
    except ParameterError:
        raise
    except Exception as err:  # (zipfile and numpy on damaged bytes: BadZipFile, zlib.error, EOFError, ValueError,
        # KeyError, a mangled header's SyntaxError, OSError, ...)
        raise ParameterError(f"{name!r}: a damaged .npz, numpy cannot read its arrays ({type(err).__name__}: {err})",
                             "frame") from None
    for key in sorted(set(files) - set(known)):
        close = difflib.get_close_matches(key, known, n=1)
        log.warning("%s: array %r is not a G-buffer and is not read%s; G-buffers: %s", name, key,
                    f" (did you mean {close[0]}?)" if close else "", ", ".join(known))
    return arrays


#: YAML 1.2's floats: PyYAML reads YAML 1.1, whose floats need a dot and a signed exponent, so a sidecar's
#: ``safety: 1e-3`` or ``weber_l: 1e-10`` (as docs/export.md writes the paper's l) was the string '1e-3',
#: refused as "expected a finite number, got '1e-3'".
_YAML_FLOAT = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""", re.X)


#: The tag :func:`read_sidecar`'s loader gives a number YAML 1.2 reads and YAML 1.1 does not (``1e-3``).
_FLOAT12_TAG = "tag:rtp,2026:float12"


class _Float12(float):
    """A number only YAML 1.2 reads (``1e-3``, ``4e12345``), with the text it was written as."""

    text: str


@functools.cache
def _sidecar_loader() -> Any:
    """PyYAML's safe loader as a metadata sidecar is read (:func:`read_sidecar`)."""
    import yaml

    class SidecarLoader(yaml.SafeLoader):
        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            # (a key given twice: PyYAML keeps the last without a word, and a sidecar's second `rate_factors:` block
            # or `default_threshold:` line silently replaced the first)
            seen: dict[str, int] = {}
            for key, _ in node.value if isinstance(node, yaml.MappingNode) else ():
                if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    if key.value in seen:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"{key.value!r} given twice, first on line {seen[key.value] + 1} (YAML keeps "
                            "only the last): give it once", key.start_mark)
                    seen[key.value] = key.start_mark.line
            return super().construct_mapping(node, deep=deep)

    def float12(loader: Any, node: Any) -> _Float12:
        text = str(loader.construct_scalar(node))
        number = _Float12(text.replace("_", ""))
        number.text = text
        return number

    # (no timestamps, as YAML 1.2's core schema: a provenance date stays the text it is, a JSON value, where a date
    # object was refused as "not JSON serializable" and 2026-02-30 raised a bare ValueError; YAML 1.1's own numbers
    # as before, then YAML 1.2's others tagged, for read_sidecar to settle)
    SidecarLoader.yaml_implicit_resolvers = {
        first: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:timestamp"]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
    SidecarLoader.add_implicit_resolver(_FLOAT12_TAG, _YAML_FLOAT, list("-+0123456789."))
    SidecarLoader.add_constructor(_FLOAT12_TAG, float12)
    return SidecarLoader


def _settle(value: Any, as_text: bool) -> Any:
    """``value`` with each YAML 1.2-only number (:class:`_Float12`) a plain float, or, ``as_text``, the text it was."""
    if isinstance(value, _Float12):
        return value.text if as_text else float(value)
    if isinstance(value, dict):
        return {_settle(k, as_text): _settle(v, as_text) for k, v in value.items()}
    if isinstance(value, list):
        return [_settle(v, as_text) for v in value]
    return value


def read_sidecar(text: str) -> Any:
    """A metadata sidecar's YAML ``text`` as Python values: PyYAML's safe loader, but floats as YAML 1.2 reads them
    (``1e-3``), dates left as text and a key given twice in one mapping refused (``yaml.YAMLError``). Inside the
    free-form ``provenance``, a number only YAML 1.2 reads stays the text it was, as YAML 1.1 reads it (an unquoted
    git hash such as ``4e12345`` was the float inf, refused as not JSON)."""
    import yaml

    data = yaml.load(text, Loader=_sidecar_loader())  # noqa: S506  (a SafeLoader)
    if isinstance(data, dict):
        return {_settle(k, False): _settle(v, k == "provenance") for k, v in data.items()}
    return _settle(data, False)
