"""GLSL sources of the renderer and the adapter, with ``#include "file"`` and ``#define``s resolved."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["load_source"]

_SHADER_DIR = Path(__file__).with_name("shaders")


def load_source(name: str, defines: dict[str, Any] | None = None) -> str:
    path = _SHADER_DIR / name
    lines = path.read_text(encoding="utf-8").splitlines()
    out: list[str] = []
    for i, line in enumerate(lines):
        if line.startswith("#include"):
            inc = line.split('"')[1]
            out.extend((_SHADER_DIR / inc).read_text(encoding="utf-8").splitlines())
            continue
        out.append(line)
        if i == 0 and defines:
            out.extend(f"#define {k} {v}" for k, v in defines.items())
    return "\n".join(out) + "\n"
