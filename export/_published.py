"""The paper's published models, recognised by the SHA-256 of their files (``published.yaml``).

``rtp-export --adopt FILE`` with no sidecar looks the file up here: a published model gets the
sidecar rtp ships for it, and its provenance records where it was published.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rtp.sdk import ModelNotFoundError, ParameterError

__all__ = ["PublishedModel", "file_sha256", "identify", "published_models"]

_REGISTRY = Path(__file__).with_name("published.yaml")


@dataclass(frozen=True)
class PublishedModel:
    """One published model file: its name, where it lives, its SHA-256 and rtp's sidecar for it."""

    name: str
    repository: str
    branch: str
    commit: str
    path: str
    sha256: str
    metadata: dict[str, Any]

    @property
    def origin(self) -> dict[str, str]:
        """Where the file was published: recorded in an adopted model's provenance."""
        return {"name": self.name, "repository": self.repository, "branch": self.branch, "commit": self.commit,
                "path": self.path, "sha256": self.sha256}


@functools.cache
def published_models() -> tuple[PublishedModel, ...]:
    """The published models rtp recognises, in the order of ``published.yaml``."""
    import yaml

    d = yaml.safe_load(_REGISTRY.read_text(encoding="utf-8"))
    return tuple(
        PublishedModel(m["name"], d["repository"], d["branch"], d["commit"], m["path"], m["sha256"], dict(m["metadata"]))
        for m in d["models"]
    )


def file_sha256(path: str | os.PathLike[str]) -> str:
    # (an int is a file descriptor to open(): identify(1) read and closed stdout)
    if not isinstance(path, (str, os.PathLike)):
        raise ParameterError(f"path: expected a file's path, got {type(path).__name__}", "path")
    if not Path(path).is_file():
        raise ModelNotFoundError(f"no file at {str(path)!r}")
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def identify(path: str | os.PathLike[str]) -> PublishedModel | None:
    """The published model whose file ``path`` is, byte for byte, or None."""
    digest = file_sha256(path)
    return next((m for m in published_models() if m.sha256 == digest), None)
