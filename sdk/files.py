"""Atomic file output, shared by every writer in rtp (checkpoints, exports, datasets, targets).

Public so that every room (and a user's own tools) writes files the same way::

    from rtp.sdk.files import atomic_output
    with atomic_output("model.onnx") as tmp:
        tmp.write_bytes(data)          # renamed over model.onnx only if this block succeeds
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_output"]


def _default_mode() -> int:
    # mkstemp creates files readable by their owner only; give the result the permissions an
    # ordinary open() would (0o666 minus the umask), so exported models stay shareable.
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is fsynced and renamed over ``path``.

    If the body raises, the temporary file is removed and ``path`` keeps its previous content, so a
    reader never sees a half-written file.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp_path, _default_mode())
        os.replace(tmp_path, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise
